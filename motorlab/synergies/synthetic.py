"""Activations and EMG made from known synergies: the ground truth a synergy pipeline must recover
(motorlab's tests and benchmarks/synergy_analysis.py use it; so can a user checking a pipeline of their own
before trusting it on recordings)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class KnownSynergies:
    synergies: np.ndarray  # (k, muscles), non-negative, unit length
    coefficients: np.ndarray  # (samples, k), non-negative
    activations: np.ndarray  # (samples, muscles): coefficients @ synergies + noise, clipped to >= 0
    episode: np.ndarray  # (samples,)
    names: list[str]


def known_synergies(seed: int = 0, episodes: int = 40, length: int = 100, noise: float = 0.02, k: int = 4,
                    muscles: int = 12) -> KnownSynergies:
    """`k` non-negative synergies over `muscles` muscles: each recruits its own muscles / k muscles strongly
    and one other muscle weakly (synergies overlap, every muscle is in one); smooth non-negative
    coefficients per episode (brief bursts at random times, so the synergies are mostly apart in time);
    Gaussian noise, clipped at 0 (activations are non-negative)."""
    rng = np.random.default_rng(seed)
    w = np.zeros((k, muscles))
    for i, own in enumerate(np.array_split(rng.permutation(muscles), k)):
        w[i, own] = rng.uniform(0.5, 1.0, size=own.size)
        other = rng.choice(np.setdiff1d(np.arange(muscles), own))
        w[i, other] = rng.uniform(0.1, 0.3)
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    t = np.linspace(0, 1, length)
    coefs = []
    for _ in range(episodes):
        c = np.zeros((length, k))
        for i in range(k):
            for _ in range(4):
                c[:, i] += rng.uniform(0.2, 1.0) * np.exp(-0.5 * ((t - rng.uniform(0, 1)) / rng.uniform(0.015, 0.05)) ** 2)
        coefs.append(c)
    c = np.concatenate(coefs)
    x = np.clip(c @ w + rng.normal(0, noise, size=(c.shape[0], muscles)), 0, None)
    return KnownSynergies(w, c, x, np.repeat(np.arange(episodes), length), [f"m{j:02d}" for j in range(muscles)])


def synthetic_emg(activations: np.ndarray, rate: float, seed: int = 1) -> np.ndarray:
    """Raw EMG from activations sampled at `rate` Hz: zero-mean Gaussian carrier noise band-limited to 30-400 Hz
    (surface EMG's band), multiplied by each muscle's activation, plus a little electrode noise; in millivolts."""
    from scipy.signal import butter, sosfilt

    rng = np.random.default_rng(seed)
    band = butter(4, (30, min(400, 0.45 * rate)), btype="bandpass", fs=rate, output="sos")
    carrier = sosfilt(band, rng.normal(0, 1, activations.shape), axis=0)
    return 1.5 * activations * carrier / carrier.std() + rng.normal(0, 0.01, activations.shape)
