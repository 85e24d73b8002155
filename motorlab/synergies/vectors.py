"""A synergy set as muscle-weight vectors (synergies x muscles), named by muscle: what heatmaps show
and what `synergies compare` matches.

Each row of a SAR's decode weight is one synergy's direction in muscle space (decode is z @ weight +
bias): NMF's non-negative components rescaled by the synergy's coefficient range, PCA's components,
PCA -> ICA's mixing directions. Scale is arbitrary per synergy (and, for PCA and ICA, sign), so rows
are shown and compared normalized."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motorlab.synergies.sar import SAR


@dataclass(frozen=True)
class SynergyVectors:
    """Rows: synergies; columns: muscles, named (None for a SAR saved without names)."""

    weights: np.ndarray  # (n_synergies, n_muscles)
    names: list[str] | None
    method: str

    @property
    def normalized(self) -> np.ndarray:
        """Each synergy scaled to unit length; a PCA or ICA direction signed so its largest weight is positive."""
        w = np.asarray(self.weights, dtype=np.float64)
        if self.method != "nmf":
            w = w * np.where(np.abs(w.max(axis=1)) >= np.abs(w.min(axis=1)), 1.0, -1.0)[:, None]
        norm = np.linalg.norm(w, axis=1, keepdims=True)
        return w / np.where(norm > 0, norm, 1.0)


def vectors_of(sar: SAR) -> SynergyVectors:
    names = sar.metadata.get("names")
    names = [str(n) for n in names] if isinstance(names, list) and len(names) == sar.n_muscles else None
    return SynergyVectors(np.asarray(sar.weight), names, sar.method)


def fitted_vectors(x: np.ndarray, method: str, n: int, seed: int) -> np.ndarray:
    """The synergy rows a fit of N synergies to x gives (motorlab's own fit, as `synergies fit` does)."""
    from motorlab.synergies.sar import fit_sar

    return np.asarray(fit_sar(x, n_synergies=n, method=method, seed=seed).weight)
