"""`motorlab dynamics fit`: train a forward model on transitions.npz.

The loss is the mean squared error of the normalized state delta, as in the reference
notebook, or with probabilistic members the Gaussian negative log-likelihood plus PETS'
penalty on the log-variance bounds; a reward head adds the normalized reward to the
targets, a termination head a logistic loss. "valid_mse" is the squared error of the
members' mean predictions of the normalized delta on held-out episodes, whatever the loss. Speed comes from keeping the
whole data set in tensors and slicing batches out of one permutation per epoch (no
DataLoader, no per-sample Python), larger batches with a larger learning rate decayed
by a cosine schedule, and an ensemble trained as one batched network.
"""

from __future__ import annotations

import copy
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
from torch.nn import functional as F

from motorlab import trackers
from motorlab.dynamics.model import DEFAULT_NONLINEARITY, ForwardModel
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


def _loss_parts(model: ForwardModel, x: torch.Tensor, y: torch.Tensor, done: torch.Tensor | None,
                pos_weight: torch.Tensor | None, nll_beta: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """(training loss, mean squared error of the normalized delta) for inputs x (K, B, in) or
    (B, in), Gaussian targets y (K, B, G) or (B, G), termination flags (K, B)."""
    mean, logvar, logit = model.split(model.net(x))
    sq = (mean - y) ** 2
    if logvar is None:
        loss = sq.mean()
    else:  # Gaussian NLL per member (mean over rows and entries), summed over members, as mbrl-lib does
        nll = sq * torch.exp(-logvar) + logvar
        if nll_beta:  # beta-NLL: each entry weighted by its variance ** beta, the weight a constant
            nll = nll * torch.exp(nll_beta * logvar.detach())
        loss = nll.mean((1, 2)).sum()
        loss = loss + 0.01 * (model.max_logvar.sum() - model.min_logvar.sum())
    if logit is not None:
        loss = loss + F.binary_cross_entropy_with_logits(logit, done.expand_as(logit), pos_weight=pos_weight)
    return loss, (loss if model.plain else sq[..., :model.state_size].mean()).detach()


def evaluate_rows(model: ForwardModel, x: torch.Tensor, y: torch.Tensor, done: torch.Tensor | None,
                  batch: int = 65536) -> dict[str, float]:
    """Held-out numbers: valid_mse (the normalized delta, averaged over members, rows and entries),
    and where the model has them valid_nll, valid_reward_mse, valid_termination_accuracy."""
    sums: dict[str, float] = {}
    with torch.no_grad():
        for i in range(0, len(x), batch):
            mean, logvar, logit = model.split(model.net(x[i:i + batch]))
            target = y[i:i + batch]
            sq = (mean - target) ** 2
            parts = {"valid_mse": sq[..., :model.state_size].mean(-1)}
            if logvar is not None:
                parts["valid_nll"] = 0.5 * (sq * torch.exp(-logvar) + logvar + math.log(2 * math.pi)).mean(-1)
            if "reward" in model.heads:
                parts["valid_reward_mse"] = sq[..., model.state_size]
            if logit is not None:
                parts["valid_termination_accuracy"] = ((logit > 0) == done[i:i + batch].bool()).float()
            for k, v in parts.items():
                sums[k] = sums.get(k, 0.0) + float(v.mean(0).sum())
    return {k: v / max(1, len(x)) for k, v in sums.items()}


def normalized_mse(model: ForwardModel, x: torch.Tensor, y: torch.Tensor, batch: int = 65536) -> float:
    """Mean squared error of the normalized delta, averaged over members, rows and entries."""
    return evaluate_rows(model, x, y, None if "termination" not in model.heads else torch.zeros(len(x)),
                         batch)["valid_mse"]


KEEP_WEIGHTS = ("best", "last")


# `dynamics fit`'s default passes: 50, or more where the data is small, so every fit takes at least
# MIN_GRADIENT_STEPS steps. 50 epochs of 400 generated-arm episodes (36,000 rows in batches of 2,000) are
# 900 steps, and those fits were still improving at their last epoch (benchmarks/mbrl_bodies.py,
# development bodies; benchmarks/devlog/mbrl_bodies.jsonl). Reacher's million rows keep their 50.
# At most MAX_AUTO_EPOCHS: each epoch also scores the held-out rows, which a tiny dataset would repeat
# thousands of times.
DEFAULT_EPOCHS, MIN_GRADIENT_STEPS, MAX_AUTO_EPOCHS = 50, 4000, 500


def auto_epochs(train_rows: int, batch_size: int) -> int:
    """Passes over `train_rows` rows that give at least MIN_GRADIENT_STEPS steps: at least DEFAULT_EPOCHS,
    at most MAX_AUTO_EPOCHS."""
    per_epoch = max(1, -(-train_rows // batch_size))
    return max(DEFAULT_EPOCHS, min(MAX_AUTO_EPOCHS, -(-MIN_GRADIENT_STEPS // per_epoch)))


def check_settings(epochs: int | None, hidden: tuple[int, ...], ensemble: int, lr: float, batch_size: int,
                   valid_fraction: float, patience: int | None, nll_beta: float = 0.0) -> None:
    """Raise MotorlabError for settings fit_model cannot use (before any file is touched)."""
    if not 0 <= nll_beta <= 1:
        raise MotorlabError(f"--nll-beta must be in [0, 1] (0: PETS' plain NLL; 0.5: beta-NLL's advice), "
                            f"got {nll_beta}.")
    if (epochs is not None and epochs <= 0) or batch_size <= 0 or ensemble <= 0 or lr <= 0:
        raise MotorlabError(f"--epochs, --batch-size, --ensemble and --lr must be positive "
                            f"(got {epochs}, {batch_size}, {ensemble}, {lr}).")
    if not 0 <= valid_fraction < 1:
        raise MotorlabError(f"--valid-fraction must be in [0, 1), got {valid_fraction}.")
    if patience is not None and (patience <= 0 or valid_fraction == 0):
        raise MotorlabError("--patience needs a positive value and a validation split (--valid-fraction > 0).")
    if any(h <= 0 for h in hidden):
        raise MotorlabError(f"--hidden widths must be positive, got {','.join(map(str, hidden))}.")


def fit_model(data: Transitions, epochs: int | None = DEFAULT_EPOCHS, hidden: tuple[int, ...] = (64, 64), ensemble: int = 1,
              lr: float = 2e-3, batch_size: int = 2000, valid_fraction: float = 0.1, patience: int | None = None,
              seed: int = 0, threads: int | None = None, run_dir: Path | None = None,
              progress: bool = True, checked: bool = False, probabilistic: bool = False,
              heads: tuple[str, ...] = (), init: ForwardModel | None = None,
              valid_episodes: np.ndarray | None = None, device: str = "cpu",
              nonlinearity: str = DEFAULT_NONLINEARITY,
              keep_weights: str = "best", nll_beta: float = 0.0) -> tuple[ForwardModel, dict[str, Any]]:
    """Train a normalized-delta forward model.

    Args:
        data: checked transitions.
        epochs: passes over the training rows (the most, with `patience`); None: `auto_epochs`.
        hidden: hidden layer widths.
        ensemble: K members, each with its own initialization and batch order.
        lr, batch_size: Adam's initial learning rate (cosine-decayed to 0 over `epochs`) and batch rows.
        valid_fraction: share of episodes held out to measure valid_mse.
        patience: stop after this many epochs without a better valid_mse, keeping the best weights.
        run_dir: where metrics.csv, tensorboard/ go (nothing is written without it).
        checked: the settings were checked already (DynamicsFitSettings checks them once).
        probabilistic: Gaussian members trained by NLL (PETS) instead of deterministic ones.
        heads: "reward" and/or "termination", fitted with the dynamics.
        init: warm start: a model of the same architecture whose weights training starts from (the
            normalizers are refit to `data`).
        valid_episodes: the held-out episode indices (instead of a `valid_fraction` draw), e.g. the
            same ones round after round of a model-based loop.
        device: where training runs ("cpu", "cuda", "auto").
        nonlinearity: the hidden layers' ("silu", the default, as `dynamics fit`'s; "tanh": Tanh + LayerNorm;
            see motorlab.dynamics.model).
        keep_weights: "best": the epoch's with the lowest valid_mse (where there are held-out rows);
            "last": the final epoch's (valid_mse is still measured and reported).
        nll_beta: probabilistic members only: beta-NLL (Seitzer et al. 2022, "On the pitfalls of
            heteroscedastic uncertainty estimation with probabilistic neural networks"): each entry's
            NLL is weighted by its predicted variance ** nll_beta (no gradient through the weight).
            Plain NLL (0) scales the mean's gradient by 1 / variance, so entries the net can call
            noisy stop training the mean; 1 gives the mean MSE's gradient. Deterministic members
            train by MSE and ignore it.

    Returns:
        The model (best weights when validating, on the CPU) and its metrics.
    """
    from motorlab.dynamics.model import device_for

    if not checked:
        check_settings(epochs, hidden, ensemble, lr, batch_size, valid_fraction, patience, nll_beta)
    if keep_weights not in KEEP_WEIGHTS:
        raise MotorlabError(f"keep_weights {keep_weights!r}: use {' or '.join(KEEP_WEIGHTS)}.")
    if threads:
        torch.set_num_threads(threads)
    torch.manual_seed(seed)
    if valid_episodes is None:
        train_rows, valid_rows = split_episodes(data.episode, valid_fraction, seed)
    else:
        is_valid = np.isin(data.episode, valid_episodes)
        train_rows, valid_rows = np.flatnonzero(~is_valid), np.flatnonzero(is_valid)
    if len(train_rows) == 0:
        raise MotorlabError("no training rows left after the validation split; collect more episodes.")
    meta = {k: data.meta.get(k) for k in ("env_id", "state_layout", "state_labels", "goal_labels", "obs_dim",
                                          "obs_layout", "action_space", "action_low", "action_high")}
    if "env" in data.meta:  # the env settings the transitions were collected under (wrappers, disturbances)
        meta["env"] = data.meta["env"]
    model = ForwardModel(data.states.shape[1], data.actions.shape[1], hidden, ensemble, meta=meta,
                         probabilistic=probabilistic, heads=heads, nonlinearity=nonlinearity)
    if init is not None:
        model.load_state_dict(init.state_dict())
    model.fit_normalizers(data.states[train_rows], data.actions[train_rows], data.next_states[train_rows],
                          data.rewards[train_rows])
    dev = device_for(device)
    model.float().to(dev)
    x, y = (t.to(dev) for t in model.training_pairs(data.states, data.actions, data.next_states, data.rewards))
    done = torch.as_tensor(data.terminated, dtype=torch.float32, device=dev)
    pos_weight = None
    if "termination" in model.heads:  # ends are rare: weigh them up to 10x, so the classifier does not ignore them
        ends = float(done[train_rows].sum())
        pos_weight = torch.tensor(min(10.0, (len(train_rows) - ends) / max(ends, 1.0)), device=dev)
    x_train, y_train, x_valid, y_valid = x[train_rows], y[train_rows], x[valid_rows], y[valid_rows]
    d_train, d_valid = done[train_rows], done[valid_rows]

    params = list(model.net.parameters()) + ([model.max_logvar, model.min_logvar] if probabilistic else [])
    optimizer = torch.optim.Adam(params, lr=lr, foreach=True)
    steps_per_epoch = max(1, -(-len(x_train) // batch_size))
    epochs = auto_epochs(len(x_train), batch_size) if epochs is None else epochs
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=epochs * steps_per_epoch)
    writer = metrics = None
    if run_dir is not None:
        from torch.utils.tensorboard import SummaryWriter

        writer = trackers.mirror(SummaryWriter(str(Path(run_dir) / "tensorboard" / "motorlab")))  # and the tracker's
        metrics = MetricsWriter(Path(run_dir) / "metrics.csv", ["epoch", "train_loss", "train_mse", "valid_mse", "lr",
                                                                "seconds"])
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
            perms = torch.stack([torch.randperm(len(x_train), generator=generator) for _ in range(ensemble)]).to(dev)
            total_loss = total_mse = 0.0
            for i in range(0, len(x_train), batch_size):
                idx = perms[:, i:i + batch_size]
                loss, sq = _loss_parts(model, x_train[idx], y_train[idx], d_train[idx], pos_weight, nll_beta)
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                schedule.step()
                total_loss += float(loss.detach()) * idx.shape[1]
                total_mse += float(sq) * idx.shape[1]
            model.net.eval()
            held_out = evaluate_rows(model, x_valid, y_valid, d_valid) if len(x_valid) else {}
            valid_mse = held_out.get("valid_mse", float("nan"))
            row = {"epoch": epoch, "train_loss": total_loss / len(x_train), "train_mse": total_mse / len(x_train),
                   "valid_mse": valid_mse, "lr": schedule.get_last_lr()[0], "seconds": time.perf_counter() - start}
            history.append({**row, **held_out})
            if metrics:
                metrics.write(row)
                for k, v in {**row, **held_out}.items():
                    if k not in ("epoch", "seconds"):
                        writer.add_scalar(f"dynamics/{k}", v, epoch)
            bar.update(task, advance=1, valid=f"{valid_mse:.2e}")
            if len(x_valid) and valid_mse < best:
                best, since_best = valid_mse, 0
                best_state = copy.deepcopy(model.state_dict()) if keep_weights == "best" else None
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
    model.cpu()
    # how far its open-loop predictions drift, on held-out episodes where there are some (the planner's
    # termination probability reads it)
    from motorlab.dynamics.open_loop import rollout_error

    drift = rollout_error(model, data, valid_rows if len(valid_rows) else train_rows, seed=seed)
    if drift is not None:
        model.meta["rollout_error"] = np.round(drift, 6).tolist()
    best_row = min(history, key=lambda r: r["valid_mse"]) if len(x_valid) else history[-1]
    kept_row = best_row if keep_weights == "best" else history[-1]  # the held-out numbers of the weights kept
    result = {"valid_mse": kept_row["valid_mse"] if len(x_valid) else None, "train_mse": history[-1]["train_mse"],
              **{k: kept_row[k] for k in ("valid_nll", "valid_reward_mse", "valid_termination_accuracy")
                 if k in kept_row},
              "epochs_run": len(history), "best_epoch": best_row["epoch"], "kept_epoch": kept_row["epoch"],
              "train_rows": int(len(x_train)), "valid_rows": int(len(x_valid)), "train_seconds": seconds,
              "history": history}
    return model, result
