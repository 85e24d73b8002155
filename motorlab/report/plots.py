"""PNG figures for runs and studies, one consistent style."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import matplotlib
import matplotlib.ticker


def files_only_backend() -> None:
    """Draw to files, never to a window (Agg), except in Jupyter: its inline backend opens no
    window either, and switching it away would hide the user's own figures from then on.
    motorlab's figures are closed once saved, so they never show up in a notebook's output."""
    if "ipykernel" not in sys.modules:
        matplotlib.use("Agg")


files_only_backend()
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from motorlab.runs import METRICS, atomic_write_bytes, read_config, read_json, read_metrics  # noqa: E402

# Legends sit on a translucent white box (no border) so they stay readable over dense data;
# constrained layout keeps suptitles and colorbars from leaving gaps or overlapping.
STYLE = {"figure.dpi": 110, "axes.grid": True, "grid.alpha": 0.3, "axes.spines.top": False,
         "axes.spines.right": False, "font.size": 10, "legend.frameon": True, "legend.framealpha": 0.85,
         "legend.edgecolor": "none", "figure.constrained_layout.use": True}


def step_count(x: float, _pos=None) -> str:
    """Environment-step tick labels people read at a glance: 0, 250k, 1M, 1.5M (not a 1e6 offset)."""
    if abs(x) >= 1e6:
        return f"{x / 1e6:.3g}M"
    if abs(x) >= 1e3:
        return f"{x / 1e3:.3g}k"
    return f"{x:.0f}"


def steps_axis(axis) -> None:
    """Label `axis` (ax.xaxis or ax.yaxis) as environment steps."""
    axis.set_major_formatter(matplotlib.ticker.FuncFormatter(step_count))

def obs_labels(env_id: str, n: int) -> list[str]:
    """Names (with units) of the observation's entries, where the env catalogue knows them."""
    from motorlab.envs.catalog import facts

    labels = facts(env_id).obs_labels
    return list(labels) if labels and len(labels) == n else [f"obs[{i}]" for i in range(n)]


CAPTION = "Description"  # the PNG text chunk holding a figure's caption (reports show it under the figure)


def save_figure(fig, path: Path, caption: str) -> Path | None:
    """Write `fig` as PNG with its one-line caption inside the file, so a report of the folder
    can say what the figure shows. A figure with no data in any panel is not written (and an
    older one at `path` is removed): an empty chart says nothing."""
    path = Path(path)
    if not any(ax.has_data() for ax in fig.axes):
        plt.close(fig)
        path.unlink(missing_ok=True)
        return None
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight", metadata={CAPTION: caption})
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
    return path


def figure_caption(path: Path) -> str | None:
    """The caption `save_figure` stored in a PNG (None for PNGs written otherwise)."""
    from PIL import Image

    try:
        with Image.open(path) as image:
            return getattr(image, "text", {}).get(CAPTION)
    except OSError:
        return None


def learning_curve(run_dir: Path, path: Path, title: str = "", solve_return: float | None = None,
                   steps_to_success: int | None = None) -> Path | None:
    """Training episode returns (and their running mean) and evaluation returns vs env steps."""
    rows = read_metrics(run_dir)
    ep = [(r["timesteps"], r["episode_return"]) for r in rows if np.isfinite(r.get("episode_return", np.nan))]
    ev = [(r["timesteps"], r["eval_return_mean"], r["eval_return_min"]) for r in rows
          if np.isfinite(r.get("eval_return_mean", np.nan))]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(7, 4))
        if ep:
            x, y = np.array(ep).T
            ax.plot(x, y, ".", ms=1.5, alpha=0.2, color="tab:blue", label="training episode")
            k = max(1, min(100, len(y) // 5))  # 100, as the rolling success rate and the comparison plots
            ax.plot(x[k - 1:], np.convolve(y, np.ones(k) / k, mode="valid"), color="tab:blue", label=f"running mean ({k})")
        if ev:
            x, m, lo = np.array(ev).T
            ax.plot(x, m, "o-", color="tab:orange", ms=4, label="evaluation mean")
            ax.plot(x, lo, "v:", color="tab:orange", ms=3, alpha=0.7, label="evaluation min")
        if solve_return is not None:
            ax.axhline(solve_return, color="gray", ls="--", lw=1, label="maximum return")
        if steps_to_success is not None:
            ax.axvline(steps_to_success, color="tab:green", lw=1, label=f"solved at {steps_to_success:,} steps")
        ax.set_xlabel("environment steps")
        steps_axis(ax.xaxis)
        ax.set_ylabel("episode return")
        ax.set_title(title or f"Learning curve: {Path(run_dir).name}")
        ax.legend(loc="best", fontsize=8)
        caption = ("Return of each training episode (dots) and its running mean, and of the deterministic "
                   "evaluations (mean and min), against environment steps"
                   + (f"; solved at {steps_to_success:,} steps" if steps_to_success is not None else "") + ".")
        return save_figure(fig, path, caption)


def plot_learning_curve(run_dir: Path) -> Path | None:
    """plots/learning_curve.png of a training run (None for runs without metrics.csv)."""
    if not (Path(run_dir) / METRICS).is_file():
        return None
    config = read_config(run_dir)
    summary = read_json(Path(run_dir) / "summary.json")
    return learning_curve(run_dir, Path(run_dir) / "plots" / "learning_curve.png",
                          title=f"{summary.get('algo', '').upper()} on {summary.get('env_id')}"
                                f"{env_tag(config.get('env', {}))} (seed {summary.get('seed')})",
                          solve_return=summary.get("solve_return"), steps_to_success=summary.get("steps_to_success"))


def env_tag(env: dict) -> str:
    """What a figure's title says of a run's env settings: " (delay 0.2 s on action, history 3)", or ""."""
    parts = []
    if env.get("delay"):
        parts.append(f"delay {env['delay']} s on {env.get('delay_on', 'action')}")
    if env.get("history", 1) > 1:
        parts.append(f"history {env['history']}")
    return f" ({', '.join(parts)})" if parts else ""


def observation_trace(observations: np.ndarray, actions: np.ndarray, dt: float, labels: list[str],
                      path: Path, title: str = "") -> Path | None:
    """Each observation element (and the action) against time for one episode; above
    MAX_TRACE_LINES elements (MyoSuite: hundreds), heatmaps of the standardized values."""
    observations = np.asarray(observations)
    n = observations.shape[1]
    t = np.arange(len(observations)) * dt
    if n > MAX_TRACE_LINES:
        return _trace_heatmaps(observations, np.asarray(actions), t, path, title)
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(n + 1, 1, figsize=(7, 1.6 * (n + 1)), sharex=True)
        for i in range(n):
            axes[i].plot(t, observations[:, i], lw=1.2)
            axes[i].set_ylabel(labels[i], fontsize=8)
        if len(actions):
            axes[n].plot(t[1:], np.asarray(actions).reshape(len(actions), -1), lw=1.2, color="tab:red")
        axes[n].set_ylabel("action", fontsize=8)
        axes[n].set_xlabel("time (s)")
        fig.suptitle(title or "Observation trace", fontsize=11)
        fig.align_ylabels(axes)
        return save_figure(fig, path, "One evaluation episode of the policy: each observation element and the "
                                      "action against time.")


MAX_TRACE_LINES = 8


def _trace_heatmaps(observations: np.ndarray, actions: np.ndarray, t: np.ndarray, path: Path, title: str
                    ) -> Path | None:
    def standardize(x: np.ndarray) -> np.ndarray:
        x = x.reshape(len(x), -1).astype(np.float64)
        std = x.std(axis=0)
        return ((x - x.mean(axis=0)) / np.where(std > 0, std, 1.0)).T

    panels = [("observation element", observations)] + ([("action element", actions)] if len(actions) else [])
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(len(panels), 1, figsize=(8, 3.2 * len(panels)), sharex=True, squeeze=False)
        for ax, (label, values) in zip(axes[:, 0], panels):
            tt = t if len(values) == len(t) else t[1:]
            image = ax.imshow(standardize(values), aspect="auto", cmap="RdBu_r", vmin=-3, vmax=3, interpolation="nearest",
                              extent=(tt[0], tt[-1] if len(tt) > 1 else tt[0] + 1e-9, values.reshape(len(values), -1).shape[1], 0))
            ax.set_ylabel(label)
            ax.grid(False)
            fig.colorbar(image, ax=ax, label="standardized value")
        axes[-1, 0].set_xlabel("time (s)")
        fig.suptitle(title or "Observation trace", fontsize=11)
        return save_figure(fig, path, "One evaluation episode of the policy: every observation and action element, "
                                      "standardized over the episode, against time.")


def comparison_bars(names: list[str], values: list[float | None], ylabel: str, path: Path, title: str,
                    caption: str, missing_label: str = "not reached", steps: bool = False,
                    notes: list[str | None] | None = None) -> Path | None:
    """One bar per study step; steps without a value are marked, not drawn as zero.
    `steps`: the values are environment steps (labelled 250k, 1.5M). `notes`: a line under each
    bar's label (e.g. "2 of 3 seeds solved"). Nothing is drawn (and an older chart at `path` is
    removed) when no step has a value."""
    if all(v is None for v in values):
        Path(path).unlink(missing_ok=True)
        return None
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(max(5, 1.1 * len(names)), 4))
        xs = np.arange(len(names))
        heights = [v if v is not None else 0.0 for v in values]
        bars = ax.bar(xs, heights, color=["tab:blue" if v is not None else "lightgray" for v in values])
        for x, v, b, note in zip(xs, values, bars, notes or [None] * len(values)):
            label = missing_label if v is None else (step_count(v) if steps else f"{v:,.0f}")
            label += f"\n{note}" if note else ""
            ax.annotate(label, (x, b.get_height()),
                        ha="center", va="bottom", fontsize=8)
        ax.set_ylim(bottom=min(0.0, *(v for v in values if v is not None)))
        if steps:
            steps_axis(ax.yaxis)
        ax.set_xticks(xs, names, rotation=25, ha="right", fontsize=8)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        return save_figure(fig, path, caption)


def grouped_bars(groups: list[str], series: dict[str, list[float | None]], ylabel: str, path: Path, title: str,
                 caption: str, percent: bool = False) -> Path | None:
    """Bars grouped by `groups` (e.g. envs), one colour per series (e.g. runs)."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(groups) * max(1, len(series)) / 2), 4))
        xs = np.arange(len(groups))
        width = 0.8 / max(1, len(series))
        for k, (name, values) in enumerate(series.items()):
            heights = [v if v is not None else 0.0 for v in values]
            bars = ax.bar(xs + (k - (len(series) - 1) / 2) * width, heights, width, label=name)
            for b, v in zip(bars, values):
                label = "-" if v is None else (f"{v:.0%}" if percent else f"{v:.3g}")
                ax.annotate(label, (b.get_x() + b.get_width() / 2, b.get_height()), ha="center", va="bottom", fontsize=7)
        ax.set_xticks(xs, groups, fontsize=8)
        ax.set_ylabel(ylabel)
        if percent:
            ax.set_ylim(0, 1.05)
            ax.yaxis.set_major_formatter(matplotlib.ticker.PercentFormatter(1.0))
        ax.set_title(title)
        ax.legend(fontsize=8)
        return save_figure(fig, path, caption)


def vaf_plot(vaf: np.ndarray, threshold: float | None, n_needed: int | None, path: Path, title: str) -> Path | None:
    """VAF against the number of synergies, with the threshold and the N that reaches it."""
    vaf = np.asarray(vaf)
    n = np.arange(1, len(vaf) + 1)
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(n, vaf, "o-", ms=3)
        if threshold is not None:
            ax.axhline(threshold, color="gray", ls="--", lw=1, label=f"threshold {threshold:.0%}")
        if n_needed is not None:
            ax.axvline(n_needed, color="tab:green", lw=1, label=f"N = {n_needed}")
        ax.set_xlabel("number of synergies N")
        ax.set_ylabel("variance accounted for")
        ax.yaxis.set_major_formatter(matplotlib.ticker.PercentFormatter(1.0))
        ax.set_ylim(min(0.0, float(vaf.min())), 1.02)
        ax.set_title(title)
        ax.legend(loc="lower right", fontsize=8)
        return save_figure(fig, path, "Variance of the recorded activations accounted for by N synergies"
                           + (f"; N = {n_needed} is the smallest reaching {threshold:.0%}." if n_needed else "."))
