"""Figures of the model-based workflow: fit loss, open-loop model error, fingertip traces, MPC distances."""

from __future__ import annotations

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
        for label, e in errors.items():  # e: (episodes, horizon)
            line, = ax.plot(horizons, e.mean(0), label=f"{label}, mean")
            if len(e) > 1:
                ax.fill_between(horizons, *np.percentile(e, [10, 90], axis=0), color=line.get_color(), alpha=0.2,
                                lw=0, label=f"10–90% of {len(e)} episodes")
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
