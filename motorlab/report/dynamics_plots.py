"""Figures of the model-based workflow: fit loss, open-loop model error, fingertip traces, MPC distances."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from motorlab.report.plots import STYLE, plt, save_figure


def loss_curve(history: list[dict], path: Path, title: str = "") -> Path | None:
    """Training and validation MSE (normalized delta units, log scale) per epoch."""
    epochs = [r["epoch"] for r in history]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6, 3.8))
        ax.semilogy(epochs, [r["train_mse"] for r in history], "-", label="training")
        valid = [r["valid_mse"] for r in history]
        if np.isfinite(valid).any():
            ax.semilogy(epochs, valid, "-", label="validation (held-out episodes)")
            best = int(np.nanargmin(valid))
            ax.plot(epochs[best], valid[best], "o", color="tab:orange", ms=5, label=f"best {valid[best]:.2e}")
        ax.set_xlabel("epoch")
        ax.set_ylabel("MSE of the normalized state delta")
        ax.set_title(title)
        ax.legend()
        return save_figure(fig, path, "Mean squared error of the model's predicted state change per epoch, on "
                                      "training transitions and on held-out episodes.")


def error_vs_horizon(horizons: np.ndarray, errors: dict[str, np.ndarray], path: Path, title: str = "",
                     ylabel: str = "error") -> Path | None:
    """Open-loop prediction error vs steps ahead: mean over episodes with the 10-90% range."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6, 3.8))
        for label, e in errors.items():  # e: (episodes, horizon), NaN after an episode's end
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # steps no episode reached: NaN, not drawn
                line, = ax.plot(horizons, np.nanmean(e, 0), label=f"{label}, mean")
                if len(e) > 1:
                    ax.fill_between(horizons, *np.nanpercentile(e, [10, 90], axis=0), color=line.get_color(),
                                    alpha=0.2, lw=0, label=f"10–90% of {len(e)} episodes")
        ax.set_xlabel("steps ahead (open loop)")
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.legend()
        return save_figure(fig, path, f"Open-loop prediction error ({', '.join(errors)}) against steps ahead: the "
                                      "model is fed the simulator's actions and never corrected; mean over "
                                      "episodes with the 10–90% range.")


def xy_traces(true_xy: np.ndarray, model_xy: np.ndarray, goals: np.ndarray | None, path: Path, title: str = "",
              labels: tuple[str, str] = ("x (m)", "y (m)")) -> Path | None:
    """The reference notebook's plot: simulator vs model paths in the plane, one colour per episode."""
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(5.2, 5))
        for e in range(len(true_xy)):
            c = f"C{e % 10}"
            ax.plot(*true_xy[e].T, "-", color=c, lw=1.5, label="simulator" if e == 0 else None)
            ax.plot(*model_xy[e].T, "--", color=c, lw=1.2, label="model (open loop)" if e == 0 else None)
            ax.plot(*true_xy[e][0], "o", color=c, ms=4)
            if goals is not None and goals.shape[-1] == 2:
                ax.plot(*goals[e], "x", color=c, ms=7, mew=2, label="target" if e == 0 else None)
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(title)
        ax.legend(loc="best")
        return save_figure(fig, path, "Paths of the same episodes in the simulator (solid) and predicted open loop "
                                      "by the model (dashed), one colour per episode.")


def distance_over_time(distances: np.ndarray, path: Path, title: str = "", dt: float | None = None) -> Path | None:
    """Fingertip-to-target distance per control step under MPC: every episode, and their median."""
    steps = np.arange(distances.shape[1])
    x = steps * dt if dt else steps
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(6, 3.8))
        ax.plot(x, distances.T * 1000, color="tab:blue", alpha=0.15, lw=0.8)
        ax.plot(x, np.median(distances, 0) * 1000, color="tab:blue", lw=2, label=f"median of {len(distances)} episodes")
        ax.set_xlabel("time (s)" if dt else "control step")
        ax.set_ylabel("distance to target (mm)")
        ax.set_yscale("log")
        ax.set_title(title)
        ax.legend()
        return save_figure(fig, path, "Distance from fingertip to target under MPC at each control step: every "
                                      "episode (thin) and their median (bold).")


def mbrl_curve(rows: list[dict], path: Path, title: str = "") -> Path | None:
    """The model-based loop round by round: the planner's return against env steps collected (with the
    collected episodes' own return), and the model's held-out error per round."""
    if not rows:
        return None
    from motorlab.report.plots import steps_axis

    steps = np.array([r["env_steps"] for r in rows], dtype=float)
    with plt.rc_context(STYLE):
        fig, (ax, err) = plt.subplots(1, 2, figsize=(10, 3.8))
        evals = np.array([np.nan if r["eval_return_mean"] is None else r["eval_return_mean"] for r in rows], float)
        if np.isfinite(evals).any():
            spread = np.array([0.0 if r["eval_return_std"] is None else r["eval_return_std"] for r in rows], float)
            done = np.isfinite(evals)  # rounds left unevaluated (--eval-every) are no gap in the line
            line, = ax.plot(steps[done], evals[done], "o-", label="MPC on the round's model (evaluation)")
            ax.fill_between(steps[done], (evals - spread)[done], (evals + spread)[done], color=line.get_color(),
                            alpha=0.2, lw=0)
        ax.plot(steps, [r["collect_return_mean"] for r in rows], "s--", color="tab:gray", ms=4,
                label="episodes collected (round 1: random)")
        ax.set_xlabel("env steps collected")
        steps_axis(ax.xaxis)
        ax.set_ylabel("return")
        ax.set_title(title)
        ax.legend(fontsize=8)
        for key, label in (("valid_mse", "all held-out episodes"), ("valid_mse_first", "the first held-out episodes")):
            values = np.array([np.nan if r[key] is None else r[key] for r in rows], float)
            if np.isfinite(values).any():
                err.semilogy(np.arange(1, len(rows) + 1), values, "o-", label=label)
        err.set_xlabel("round")
        err.set_ylabel("held-out MSE (normalized state delta)")
        if err.lines:  # no episode held out yet (one a round, fewer rounds than the hold-out interval)
            err.legend(fontsize=8)
        return save_figure(fig, path, "Left: return of MPC on each round's model against the env steps collected so "
                                      "far (mean ± std over the evaluation episodes), and of the episodes each round "
                                      "collected. Right: the model's error on held-out episodes after each round.")


def error_by_dimension(by_dim: np.ndarray, labels: list[str], path: Path, title: str = "") -> Path | None:
    """Open-loop error of each state entry against steps ahead (normalized RMSE over episodes): one
    line per entry for a few, a heat map for many."""
    horizons = np.arange(len(by_dim))
    with plt.rc_context(STYLE):
        if len(labels) <= 8:
            fig, ax = plt.subplots(figsize=(6, 3.8))
            for i, label in enumerate(labels):
                ax.plot(horizons, by_dim[:, i], label=label)
            ax.set_ylabel("normalized RMSE")
            ax.legend(fontsize=8)
        else:
            fig, ax = plt.subplots(figsize=(7, 0.25 * len(labels) + 1.5))
            image = ax.imshow(by_dim.T, aspect="auto", interpolation="nearest", cmap="magma",
                              extent=(-0.5, len(by_dim) - 0.5, len(labels) - 0.5, -0.5))
            ax.set_yticks(range(len(labels)), labels, fontsize=7)
            fig.colorbar(image, ax=ax, label="normalized RMSE")
        ax.set_xlabel("steps ahead (open loop)")
        ax.set_title(title)
        return save_figure(fig, path, "Error of the model's open-loop prediction of each state entry against steps "
                                      "ahead, in units of the entry's spread in the training data (RMSE over "
                                      "episodes).")
