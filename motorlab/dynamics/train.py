"""`motorlab dynamics fit`: train a forward model on transitions.npz.

The loss is the mean squared error of the normalized state delta, as in the reference
notebook; "valid_mse" is that loss on held-out episodes. Speed comes from keeping the
whole data set in tensors and slicing batches out of one permutation per epoch (no
DataLoader, no per-sample Python), larger batches with a larger learning rate decayed
by a cosine schedule, and an ensemble trained as one batched network.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from motorlab.dynamics.model import ForwardModel
from motorlab.dynamics.transitions import Transitions
from motorlab.errors import MotorlabError
from motorlab.runs import MetricsWriter


def split_episodes(episode: np.ndarray, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Row indices (train, valid): whole episodes go to validation, so it measures unseen rollouts."""
    ids = np.unique(episode)
    rng = np.random.default_rng(seed)
    n_valid = int(round(fraction * len(ids)))
    if fraction > 0 and len(ids) > 1:
        n_valid = min(max(n_valid, 1), len(ids) - 1)
    valid_ids = rng.choice(ids, size=n_valid, replace=False)
    is_valid = np.isin(episode, valid_ids)
    return np.flatnonzero(~is_valid), np.flatnonzero(is_valid)


def normalized_mse(model: ForwardModel, x: torch.Tensor, y: torch.Tensor, batch: int = 65536) -> float:
    """Mean squared error of the normalized delta, averaged over members, rows and entries."""
    with torch.no_grad():
        total = sum(float(((model.net(x[i:i + batch]) - y[i:i + batch]) ** 2).sum()) for i in range(0, len(x), batch))
    return total / (model.members * max(1, y.numel()))


def check_settings(epochs: int, hidden: tuple[int, ...], ensemble: int, lr: float, batch_size: int,
                   valid_fraction: float, patience: int | None) -> None:
    """Raise MotorlabError for settings fit_model cannot use (before any file is touched)."""
    if epochs <= 0 or batch_size <= 0 or ensemble <= 0 or lr <= 0:
        raise MotorlabError(f"--epochs, --batch-size, --ensemble and --lr must be positive "
                            f"(got {epochs}, {batch_size}, {ensemble}, {lr}).")
    if not 0 <= valid_fraction < 1:
        raise MotorlabError(f"--valid-fraction must be in [0, 1), got {valid_fraction}.")
    if patience is not None and (patience <= 0 or valid_fraction == 0):
        raise MotorlabError("--patience needs a positive value and a validation split (--valid-fraction > 0).")
    if any(h <= 0 for h in hidden):
        raise MotorlabError(f"--hidden widths must be positive, got {','.join(map(str, hidden))}.")


def fit_model(data: Transitions, epochs: int = 50, hidden: tuple[int, ...] = (64, 64), ensemble: int = 1,
              lr: float = 2e-3, batch_size: int = 2000, valid_fraction: float = 0.1, patience: int | None = None,
              seed: int = 0, threads: int | None = None, run_dir: Path | None = None,
              progress: bool = True, checked: bool = False) -> tuple[ForwardModel, dict[str, Any]]:
    """Train a normalized-delta forward model.

    Args:
        data: checked transitions.
        epochs: passes over the training rows (the most, with `patience`).
        hidden: hidden layer widths.
        ensemble: K members, each with its own initialization and batch order.
        lr, batch_size: Adam's initial learning rate (cosine-decayed to 0 over `epochs`) and batch rows.
        valid_fraction: share of episodes held out to measure valid_mse.
        patience: stop after this many epochs without a better valid_mse, keeping the best weights.
        run_dir: where metrics.csv, tensorboard/ go (nothing is written without it).
        checked: the settings were checked already (DynamicsFitSettings checks them once).

    Returns:
        The model (best weights when validating) and its metrics.
    """
    if not checked:
        check_settings(epochs, hidden, ensemble, lr, batch_size, valid_fraction, patience)
    if threads:
        torch.set_num_threads(threads)
    torch.manual_seed(seed)
    train_rows, valid_rows = split_episodes(data.episode, valid_fraction, seed)
    if len(train_rows) == 0:
        raise MotorlabError("no training rows left after the validation split; collect more episodes.")
    meta = {k: data.meta.get(k) for k in ("env_id", "state_layout", "state_labels", "goal_labels", "obs_dim",
                                          "action_low", "action_high")}
    model = ForwardModel(data.states.shape[1], data.actions.shape[1], hidden, ensemble, meta=meta)
    model.fit_normalizers(data.states[train_rows], data.actions[train_rows], data.next_states[train_rows])
    model.float()
    x, y = model.training_pairs(data.states, data.actions, data.next_states)
    x_train, y_train, x_valid, y_valid = x[train_rows], y[train_rows], x[valid_rows], y[valid_rows]

    optimizer = torch.optim.Adam(model.net.parameters(), lr=lr, foreach=True)
    steps_per_epoch = max(1, -(-len(x_train) // batch_size))
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=epochs * steps_per_epoch)
    writer = metrics = None
    if run_dir is not None:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(Path(run_dir) / "tensorboard" / "motorlab"))
        metrics = MetricsWriter(Path(run_dir) / "metrics.csv", ["epoch", "train_mse", "valid_mse", "lr", "seconds"])
    generator = torch.Generator().manual_seed(seed)
    best, best_state, since_best, history = float("inf"), None, 0, []
    start = time.perf_counter()
    columns = (TextColumn("fit {task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} epochs"),
               TextColumn("valid {task.fields[valid]}"), TimeRemainingColumn())
    with Progress(*columns, disable=not progress) as bar:
        task = bar.add_task(f"{model.members}x{list(hidden)}", total=epochs, valid="-")
        for epoch in range(1, epochs + 1):
            model.net.train()
            # one permutation per member: each sees its own batch order
            perms = torch.stack([torch.randperm(len(x_train), generator=generator) for _ in range(ensemble)])
            total = 0.0
            for i in range(0, len(x_train), batch_size):
                idx = perms[:, i:i + batch_size]
                loss = ((model.net(x_train[idx]) - y_train[idx]) ** 2).mean()
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                schedule.step()
                total += float(loss.detach()) * idx.shape[1]
            model.net.eval()
            train_mse = total / len(x_train)
            valid_mse = normalized_mse(model, x_valid, y_valid) if len(x_valid) else float("nan")
            row = {"epoch": epoch, "train_mse": train_mse, "valid_mse": valid_mse,
                   "lr": schedule.get_last_lr()[0], "seconds": time.perf_counter() - start}
            history.append(row)
            if metrics:
                metrics.write(row)
                for k in ("train_mse", "valid_mse", "lr"):
                    writer.add_scalar(f"dynamics/{k}", row[k], epoch)
            bar.update(task, advance=1, valid=f"{valid_mse:.2e}")
            if len(x_valid) and valid_mse < best:
                best, best_state, since_best = valid_mse, copy.deepcopy(model.state_dict()), 0
            else:
                since_best += 1
            if patience is not None and since_best >= patience:
                break
    seconds = time.perf_counter() - start
    if metrics:
        metrics.close()
        writer.close()
    if best_state is not None:
        model.load_state_dict(best_state)
    result = {"valid_mse": best if len(x_valid) else None, "train_mse": history[-1]["train_mse"],
              "epochs_run": len(history), "best_epoch": (min(history, key=lambda r: r["valid_mse"])["epoch"]
                                                        if len(x_valid) else len(history)),
              "train_rows": int(len(x_train)), "valid_rows": int(len(x_valid)), "train_seconds": seconds,
              "history": history}
    return model, result
