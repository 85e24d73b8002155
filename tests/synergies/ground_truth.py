"""Activations made from known synergies: what the synergy analyses must recover."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MUSCLES = [f"m{j:02d}" for j in range(12)]


@dataclass(frozen=True)
class GroundTruth:
    synergies: np.ndarray  # (4, muscles), non-negative, unit length
    coefficients: np.ndarray  # (samples, 4), non-negative
    activations: np.ndarray  # (samples, muscles): coefficients @ synergies + noise, clipped to >= 0
    episode: np.ndarray  # (samples,)
    names: list[str]


def ground_truth(seed: int = 0, episodes: int = 40, length: int = 100, noise: float = 0.02, k: int = 4) -> GroundTruth:
    """`k` non-negative synergies over 12 muscles: each recruits its own 12 / k muscles strongly and one
    other muscle weakly (synergies overlap, every muscle is in one), smooth non-negative coefficients
    per episode (sums of random bumps), and Gaussian noise clipped at 0."""
    rng = np.random.default_rng(seed)
    m = len(MUSCLES)
    w = np.zeros((k, m))
    for i, own in enumerate(np.array_split(rng.permutation(m), k)):
        w[i, own] = rng.uniform(0.5, 1.0, size=own.size)
        other = rng.choice(np.setdiff1d(np.arange(m), own))
        w[i, other] = rng.uniform(0.1, 0.3)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    t = np.linspace(0, 1, length)
    coefs = []
    for _ in range(episodes):
        c = np.zeros((length, k))
        for i in range(k):
            for _ in range(4):  # brief bursts at random times, widths and heights (synergies mostly apart in time)
                c[:, i] += rng.uniform(0.2, 1.0) * np.exp(-0.5 * ((t - rng.uniform(0, 1)) / rng.uniform(0.015, 0.05)) ** 2)
        coefs.append(c)
    c = np.concatenate(coefs)
    x = np.clip(c @ w + rng.normal(0, noise, size=(c.shape[0], m)), 0, None)
    return GroundTruth(w, c, x, np.repeat(np.arange(episodes), length), list(MUSCLES))
