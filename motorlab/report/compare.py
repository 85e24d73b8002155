"""Learning curves of several settings across seeds: mean and a 95% confidence band.

Each run's training episodes (metrics.csv) are put on a common grid of env steps
(the running mean of the last episodes up to each grid point), then averaged over
seeds; the band is the t-interval of that mean (none for a single seed).
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from motorlab.errors import MotorlabError
from motorlab.report.plots import STYLE, plt, save_figure, steps_axis
from motorlab.runs import read_json, read_metrics, require_run_dir
from motorlab.stats import aggregate, trial_scores

GRID_POINTS = 100


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


def mean_and_band(curves: np.ndarray, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Mean over seeds (rows) and the half-width of its t confidence interval (0 for one seed)."""
    n = np.sum(np.isfinite(curves), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # grid points before any seed's first episode
        mean = np.nanmean(curves, axis=0)
        sem = np.nanstd(curves, axis=0, ddof=1) / np.sqrt(n) if len(curves) > 1 else np.zeros(curves.shape[1])
    half = np.where(n > 1, stats.t.ppf(0.5 + confidence / 2, np.maximum(n - 1, 1)) * sem, 0.0)
    return mean, np.nan_to_num(half)


def compare_curves(groups: dict[str, list[Path]], path: Path, title: str = "Learning curves") -> dict:
    """Plot return and success rate vs env steps per group (seeds averaged); write `path` (PNG).
    The success panel only where the envs have a success flag (else training success means nothing).

    Returns:
        Per group: seeds and the final mean return / success rate.

    Raises:
        MotorlabError: empty groups or a run folder without metrics.csv.
    """
    if not groups or any(not runs for runs in groups.values()):
        raise MotorlabError("each comparison group needs at least one run folder.")
    # each run's metrics.csv rows, read once
    runs = {g: [read_metrics(require_run_dir(Path(r))) for r in rs] for g, rs in groups.items()}
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


def group_statistics(groups: dict[str, list[Path | str]]) -> dict[str, Any]:
    """rliable across each group's seeds: IQM with 95% CI of the final evaluation return and
    success rate, and the probability that one group beats another (e.g. SAR-RL vs RL-E2E).

    Returns:
        Flat keys "<group>.final_return_iqm", "..._iqm_ci_low", "<A>.final_return_p_better_than[<B>]", ...
    """
    scores = {g: [trial_scores(read_json(Path(d) / "summary.json")) for d in ds] for g, ds in groups.items()}
    flat, _ = aggregate(scores)
    return {k: v for k, v in flat.items() if "steps_to_success" not in k and not k.endswith(".seeds")}
