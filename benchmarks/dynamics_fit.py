"""Forward-model training on Reacher-v5: motorlab's `fit_model` vs the skorch reference.

Both sides get the same transitions (collected by motorlab, 20,000 random episodes by
default), the same episode-wise validation split and the same normalization (statistics
of the training rows), and report the validation MSE of the normalized state delta.

Reference (the notebook): nn.Sequential 10 -> 64 Tanh LayerNorm -> 64 Tanh LayerNorm -> 8,
skorch NeuralNetRegressor, Adam, lr 1e-4, batch 500, 50 epochs, no internal split.
motorlab: the same network, `motorlab dynamics fit` defaults.

Usage:  .venv/bin/python benchmarks/dynamics_fit.py [--episodes 20000] [--reference-epochs 50]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch
from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path
from torch import nn

from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.train import fit_model, normalized_mse, split_episodes

TARGET_SPEEDUP = 5.0


def reference_fit(x_train, y_train, epochs: int, seed: int) -> tuple[nn.Module, float]:
    from skorch import NeuralNetRegressor

    torch.manual_seed(seed)
    module = nn.Sequential(nn.Linear(x_train.shape[1], 64), nn.Tanh(), nn.LayerNorm(64), nn.Linear(64, 64), nn.Tanh(),
                           nn.LayerNorm(64), nn.Linear(64, y_train.shape[1]))
    net = NeuralNetRegressor(module, optimizer=torch.optim.Adam, lr=1e-4, batch_size=500, max_epochs=epochs,
                             train_split=None, verbose=0, device="cpu")
    start = time.perf_counter()
    net.fit(x_train, y_train)
    return net.module_, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20000)
    parser.add_argument("--reference-epochs", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    recorder = Recorder("dynamics_fit")  # the git state and load, read as the run starts

    data = collect_transitions("Reacher-v5", args.episodes, seed=args.seed, progress=False)

    start = time.perf_counter()
    model, result = fit_model(data, seed=args.seed, progress=False)
    ours_seconds = time.perf_counter() - start

    # the reference sees exactly motorlab's normalized inputs and targets and split
    train_rows, valid_rows = split_episodes(data.episode, 0.1, args.seed)
    x, y = model.training_pairs(data.states, data.actions, data.next_states)
    module, ref_seconds = reference_fit(x[train_rows].numpy(), y[train_rows].numpy(), args.reference_epochs, args.seed)
    with torch.no_grad():
        ref_mse = float(((module(x[valid_rows]) - y[valid_rows]) ** 2).mean())
    ours_mse = normalized_mse(model, x[valid_rows], y[valid_rows])
    recorder.record({
        "benchmark": "dynamics_fit", "env_id": "Reacher-v5", "transitions": len(data),
        "train_rows": len(train_rows), "valid_rows": len(valid_rows), "cpus": os.cpu_count(),
        "torch_threads": torch.get_num_threads(), "machine": platform.processor() or platform.machine(),
        "motorlab_seconds": ours_seconds, "motorlab_valid_mse": ours_mse, "motorlab_epochs": result["epochs_run"],
        "reference_seconds": ref_seconds, "reference_valid_mse": ref_mse, "reference_epochs": args.reference_epochs,
        "speedup": ref_seconds / ours_seconds, "mse_ratio": ours_mse / ref_mse, "target_speedup": TARGET_SPEEDUP,
        "meets_target": ref_seconds / ours_seconds >= TARGET_SPEEDUP and ours_mse <= ref_mse,
    })


if __name__ == "__main__":
    main()
