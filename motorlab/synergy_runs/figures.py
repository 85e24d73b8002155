"""The figures a synergy analysis is read from: the muscle-weight heatmap (muscles named, in the
model's order), each synergy's activation coefficients over a few episodes, and the VAF curve with its
cross-validated band and the N each criterion chose."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motorlab.report.plots import STYLE, plt, save_figure
from motorlab.synergies.analysis import Choice, CrossValidatedVaf
from motorlab.synergies.vectors import SynergyVectors

CRITERION_COLOURS = {"total-vaf": "tab:green", "muscle-vaf": "tab:orange", "elbow": "tab:purple"}


def heatmap(vectors: SynergyVectors, path: Path, title: str) -> Path | None:
    """Muscles (rows, named, in the model's order) x synergies (columns): each synergy's weights scaled
    to unit length; a diverging colour map where weights may be negative (PCA, ICA)."""
    w = vectors.normalized.T  # (muscles, synergies)
    names = vectors.names or [f"muscle {j}" for j in range(w.shape[0])]
    signed = bool((w < -1e-12).any())
    limit = float(np.abs(w).max()) or 1.0
    with plt.rc_context({**STYLE, "axes.grid": False}):
        fig, ax = plt.subplots(figsize=(1.2 + 0.45 * w.shape[1], 1.0 + 0.22 * w.shape[0]))
        image = ax.imshow(w, aspect="auto", cmap="RdBu_r" if signed else "viridis",
                          vmin=-limit if signed else 0.0, vmax=limit, interpolation="nearest")
        ax.set_yticks(range(len(names)), names, fontsize=7)
        ax.set_xticks(range(w.shape[1]), [f"S{i + 1}" for i in range(w.shape[1])], fontsize=7)
        ax.set_xlabel("synergy")
        ax.set_ylabel("muscle")
        ax.set_title(title, fontsize=9)
        fig.colorbar(image, ax=ax, label="weight (unit-length synergy)", shrink=0.6)
        # the caption names each synergy's strongest muscle: what a reader looks for first, in text a page can search
        top = "; ".join(f"S{i + 1} {names[int(np.argmax(np.abs(w[:, i])))]}" for i in range(w.shape[1]))
        return save_figure(fig, path, f"Muscle weights of {w.shape[1]} synergies over {w.shape[0]} muscles "
                                      f"(unit-length synergies, the model's order); strongest: {top}.")


def coefficients(z: np.ndarray, episodes: np.ndarray, path: Path, title: str, shown: int = 3,
                 rate: float | None = None) -> Path | None:
    """Each synergy's activation coefficient over the first `shown` episodes (one panel per episode)."""
    first = list(dict.fromkeys(np.asarray(episodes).tolist()))[:shown]
    if not first:
        return None
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(len(first), 1, figsize=(8, 1.8 * len(first)), sharex=False, squeeze=False)
        for ax, ep in zip(axes[:, 0], first):
            rows = z[np.asarray(episodes) == ep]
            t = np.arange(len(rows)) / rate if rate else np.arange(len(rows))
            for i in range(rows.shape[1]):
                ax.plot(t, rows[:, i], lw=1, label=f"S{i + 1}")
            ax.set_ylabel(f"episode {ep}", fontsize=8)
        axes[-1, 0].set_xlabel("time (s)" if rate else "step")
        axes[0, 0].set_title(title, fontsize=9)
        axes[0, 0].legend(loc="upper right", fontsize=6, ncol=min(8, z.shape[1]))
        return save_figure(fig, path, f"Activation coefficients of {z.shape[1]} synergies over {len(first)} episodes.")


def vaf_with_band(cv: CrossValidatedVaf, chosen: list[Choice], path: Path, title: str) -> Path | None:
    """The VAF curve (the folds' mean) with a band of +-1 SD over folds, the training VAF beside it, the
    total-VAF threshold, and a line at the N each criterion chose."""
    ns = np.asarray(cv.ns)
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(7, 4))
        label = f"held out ({cv.folds} folds of episodes)" if cv.held_out else "in-sample"
        ax.plot(ns, cv.mean, "o-", ms=3, label=label)
        if cv.held_out:
            ax.fill_between(ns, cv.mean - cv.std, cv.mean + cv.std, alpha=0.25, label="±1 SD over folds")
            ax.plot(ns, cv.train.mean(axis=0), ":", lw=1, color="gray", label="fitted folds")
        for c in chosen:
            if c.criterion == "total-vaf":
                ax.axhline(c.threshold, color="gray", ls="--", lw=0.8)
            if c.n is not None:
                ax.axvline(c.n, color=CRITERION_COLOURS[c.criterion], lw=1.2, ls="-.",
                           label=f"{c.criterion}: N = {c.n}")
        ax.set_xlabel("number of synergies N")
        ax.set_ylabel(f"VAF ({cv.definition})")
        ax.set_ylim(min(0.0, float(np.min(cv.mean - cv.std))), 1.02)
        ax.set_title(title, fontsize=9)
        ax.legend(loc="lower right", fontsize=7)
        made = ", ".join(f"{c.criterion} N = {c.n}" for c in chosen)
        return save_figure(fig, path, f"{cv.where.capitalize()} against N; chosen: {made}.")
