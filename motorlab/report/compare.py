"""Learning curves of several settings across seeds: mean and a 95% confidence band.

Two curves: "training", each run's training episodes (metrics.csv) put on a common grid of env
steps (the running mean of the last episodes up to each grid point); or "evaluation", each run's
evaluations (a train run's metrics.csv rows with eval_return_mean, an mbrl loop's curve.csv rows,
one per round), held from one evaluation to the next: at each grid point the last evaluation at
or before it. Then averaged over seeds; the band is the t-interval of that mean (none for a single
seed). A group may mix train and mbrl run folders.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Literal

import numpy as np
from scipy import stats

from motorlab.errors import MotorlabError
from motorlab.report.plots import STYLE, plt, save_figure, steps_axis
from motorlab.runs import METRICS, SUMMARY, read_json, read_metrics, read_number_rows, require_run_dir
from motorlab.stats import aggregate, trial_scores

GRID_POINTS = 100
Curve = Literal["training", "evaluation"]
LOOP_CURVE = "curve.csv"  # an mbrl loop's rounds (motorlab.planning.mbrl.CURVE, a layer above)
LOOP_MODEL = "model"  # an mbrl loop's last model, what "@loop" names in a recipe


def _curve(metrics: list[dict], column: str, grid: np.ndarray, window: int = 100) -> np.ndarray:
    """Running mean (last `window` episodes) of `column` of a run's metrics.csv rows at each grid
    step; NaN before the first episode."""
    rows = [r for r in metrics if np.isfinite(r.get(column, np.nan))]
    if not rows:
        return np.full(len(grid), np.nan)
    steps = np.array([r["timesteps"] for r in rows])
    values = np.array([r[column] for r in rows])
    cums = np.concatenate([[0.0], np.cumsum(values)])
    idx = np.searchsorted(steps, grid, side="right")  # episodes finished by each grid step
    lo = np.maximum(idx - window, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (cums[idx] - cums[lo]) / (idx - lo)
    out[idx == 0] = np.nan
    out[grid > steps[-1]] = np.nan  # this run logged nothing past here: no extrapolation
    return out


def run_folder(path: Path | str) -> Path:
    """The run folder `path` stands for: an mbrl loop's model/ (what a recipe's "@loop" gives a
    compare step) stands for its loop's folder; anything else for itself."""
    path = Path(path)
    if path.name == LOOP_MODEL and (path.parent / LOOP_CURVE).is_file() and not (path / SUMMARY).is_file():
        return path.parent
    return path


def evaluations(run: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """A finished run's evaluations: (env steps, mean evaluation return), in step order. A train run's
    metrics.csv rows with eval_return_mean (against timesteps), an mbrl loop's curve.csv rows
    (against env_steps collected).

    Raises:
        MotorlabError: not a finished train or mbrl run folder, or one without evaluations.
    """
    folder = require_run_dir(run_folder(run))
    if (folder / METRICS).is_file():
        rows, step, where = read_metrics(folder), "timesteps", METRICS
        fix = "train it with evaluations (--eval-every N, eval_every = N in a recipe)"
    elif (folder / LOOP_CURVE).is_file():
        rows, step, where = read_number_rows(folder / LOOP_CURVE), "env_steps", LOOP_CURVE
        fix = "run the loop with evaluations (--eval-episodes N, at least 1)"
    else:
        raise MotorlabError(f"{folder} has neither {METRICS} (a train run) nor {LOOP_CURVE} (an mbrl run): give "
                            "train or mbrl run folders to compare their evaluation curves.")
    points = sorted((r[step], r["eval_return_mean"]) for r in rows
                    if np.isfinite(r.get("eval_return_mean", np.nan)) and np.isfinite(r.get(step, np.nan)))
    if not points:
        raise MotorlabError(f"{folder}/{where} holds no evaluation (eval_return_mean): {fix}, or compare with "
                            "curve = \"training\" (--curve training).")
    steps, values = np.array(points).T
    return steps, values


def held(steps: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """At each grid point the last evaluation at or before it; NaN before the first and after the last."""
    idx = np.searchsorted(steps, grid, side="right") - 1
    out = np.where(idx >= 0, values[np.maximum(idx, 0)], np.nan)
    out[grid > steps[-1]] = np.nan  # the run ended there: no extrapolation
    return out


def _training_metrics(run: Path | str) -> list[dict[str, float]]:
    """A train run's metrics.csv rows (an mbrl loop has none: one line saying to compare its evaluations)."""
    folder = require_run_dir(run_folder(run))
    if not (folder / METRICS).is_file() and (folder / LOOP_CURVE).is_file():
        raise MotorlabError(f"{folder} is a model-based loop (mbrl): it has no training episodes ({METRICS}) to "
                            "plot; compare evaluations instead: curve = \"evaluation\" (--curve evaluation).")
    return read_metrics(folder)


def check_runs(groups: dict[str, list[Path]], curve: Curve = "training") -> None:
    """Every group has run folders with the curve's data (before a compare writes anything).

    Raises:
        MotorlabError: as compare_curves does.
    """
    if not groups or any(not runs for runs in groups.values()):
        raise MotorlabError("each comparison group needs at least one run folder.")
    read = evaluations if curve == "evaluation" else _training_metrics
    for run in (r for rs in groups.values() for r in rs):
        read(run)


def mean_and_band(curves: np.ndarray, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Mean over seeds (rows) and the half-width of its t confidence interval (0 for one seed)."""
    n = np.sum(np.isfinite(curves), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # grid points before any seed's first episode
        mean = np.nanmean(curves, axis=0)
        sem = np.nanstd(curves, axis=0, ddof=1) / np.sqrt(n) if len(curves) > 1 else np.zeros(curves.shape[1])
    half = np.where(n > 1, stats.t.ppf(0.5 + confidence / 2, np.maximum(n - 1, 1)) * sem, 0.0)
    return mean, np.nan_to_num(half)


def compare_curves(groups: dict[str, list[Path]], path: Path, title: str = "Learning curves",
                   curve: Curve = "training") -> dict:
    """Plot return (and success rate) vs env steps per group (seeds averaged); write `path` (PNG).

    Args:
        curve: "training": the running mean of training episodes (train runs' metrics.csv), with a
            success panel where the envs have a success flag (else training success means nothing);
            "evaluation": each run's evaluation returns, held until its next evaluation (train runs'
            metrics.csv, mbrl loops' curve.csv; a group may mix them).

    Returns:
        Per group: seeds and the final mean return (training: final_episode_return and
        final_episode_success; evaluation: final_eval_return_mean).

    Raises:
        MotorlabError: empty groups, a folder that is not a finished run of the right kind (one line
            naming it and the fix).
    """
    if not groups or any(not runs for runs in groups.values()):
        raise MotorlabError("each comparison group needs at least one run folder.")
    if curve == "evaluation":
        return _evaluation_curves(groups, path, title)
    # each run's metrics.csv rows, read once
    runs = {g: [_training_metrics(r) for r in rs] for g, rs in groups.items()}
    last = max(max(r["timesteps"] for r in run) for rs in runs.values() for run in rs)
    grid = np.linspace(0, last, GRID_POINTS)
    # training success only where the envs judged episodes (their success flag): else no panel, no number
    judged = any(np.isfinite(r.get("episode_success", np.nan)) for rs in runs.values() for run in rs for r in run)
    result = {}
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, 2 if judged else 1, figsize=(11 if judged else 6, 4), squeeze=False)
        panels = list(zip(axes[0], ("episode_return", "episode_success")))
        for label, rs in runs.items():
            n = len(rs)
            for ax, column in panels:
                mean, half = mean_and_band(np.array([_curve(r, column, grid) for r in rs]))
                line, = ax.plot(grid, mean, label=f"{label} ({n} seed{'s' if n > 1 else ''})")
                ax.fill_between(grid, mean - half, mean + half, color=line.get_color(), alpha=0.2, lw=0)
                finite = mean[np.isfinite(mean)]
                result.setdefault(label, {"seeds": n})[f"final_{column}"] = float(finite[-1]) if finite.size else None
        axes[0][0].set_ylabel("episode return (running mean of 100)")
        if judged:
            axes[0][1].set_ylabel("success rate (last 100 episodes)")
            axes[0][1].set_ylim(-0.02, 1.02)
        for ax, _ in panels:
            ax.set_xlabel("environment steps")
            steps_axis(ax.xaxis)
            ax.legend(fontsize=8)
        fig.suptitle(f"{title} — mean and 95% confidence band over seeds", fontsize=11)
        save_figure(fig, path, f"Training return{' and success' if judged else ''} (running means over episodes) "
                               "against environment steps, per setting: the mean over its seeds with a 95% confidence band.")
    return result


def _evaluation_curves(groups: dict[str, list[Path]], path: Path, title: str) -> dict:
    """compare_curves' "evaluation" curves: each run's evaluations on a common grid (evenly spaced
    steps and every run's evaluation steps), the last evaluation at or before each point."""
    runs = {g: [evaluations(r) for r in rs] for g, rs in groups.items()}
    every = [steps for rs in runs.values() for steps, _ in rs]
    last = max(float(steps[-1]) for steps in every)
    grid = np.unique(np.concatenate([np.linspace(0, last, GRID_POINTS), *every]))
    result = {}
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6, 4))
        for label, rs in runs.items():
            n = len(rs)
            mean, half = mean_and_band(np.array([held(steps, values, grid) for steps, values in rs]))
            line, = ax.plot(grid, mean, drawstyle="steps-post", label=f"{label} ({n} seed{'s' if n > 1 else ''})")
            ax.fill_between(grid, mean - half, mean + half, step="post", color=line.get_color(), alpha=0.2, lw=0)
            finite = mean[np.isfinite(mean)]
            result[label] = {"seeds": n, "final_eval_return_mean": float(finite[-1]) if finite.size else None}
        ax.set_ylabel("evaluation return (mean over its episodes)")
        ax.set_xlabel("environment steps")
        steps_axis(ax.xaxis)
        ax.legend(fontsize=8)
        fig.suptitle(f"{title} — mean and 95% confidence band over seeds", fontsize=11)
        save_figure(fig, path, "Evaluation return against environment steps, per setting (each run's last evaluation "
                               "at each step): the mean over its seeds with a 95% confidence band.")
    return result


def group_statistics(groups: dict[str, list[Path | str]]) -> dict[str, Any]:
    """rliable across each group's seeds: IQM with 95% CI of the final evaluation return and
    success rate, and the probability that one group beats another (e.g. SAR-RL vs RL-E2E).

    Returns:
        Flat keys "<group>.final_return_mean", "_iqm" (4+ seeds), "_iqm_ci_low" and "_high" (5+ seeds),
        "<A>.final_return_p_better_than[<B>]", ...
    """
    scores = {g: [trial_scores(_scored(read_json(run_folder(d) / SUMMARY))) for d in ds] for g, ds in groups.items()}
    flat, _ = aggregate(scores)
    return {k: v for k, v in flat.items() if "steps_to_success" not in k and not k.endswith(".seeds")}


def _scored(summary: dict[str, Any]) -> dict[str, Any]:
    """A run's summary as rliable's scores read it: an mbrl loop's final return (MPC on its last
    model) is its return."""
    if "final_return_mean" in summary and "return_mean" not in summary and "eval_return_mean" not in summary:
        return {**summary, "return_mean": summary["final_return_mean"]}
    return summary
