"""Intervals that claim no more than the seeds and episodes show.

- **Across seeds** (`across_seeds`): the IQM only where it trims something (>= 4 seeds; rliable's
  IQM of 3 values is their mean), else the mean, named as such. From MIN_SEEDS_FOR_INTERVAL (5)
  seeds a 95% stratified-bootstrap interval (rliable), where it has a width. With 2-4 seeds the
  bootstrap's "95% interval" is little more than the lowest and highest seed, so none is given: the
  seeds' range is, named as the range. One seed: no interval at all.
- **k of n** (`wilson`): scipy's Wilson score interval for a binomial proportion, at any n: seeds
  that solved (motorlab.stats.StepsToThreshold) and episodes pooled over seeds (`pooled_rate`).
- **P(A > B)** (`p_better`): rliable's probability of improvement, with its interval from 5 seeds
  per side; "all tied" when every value of both sides is the same, "do not overlap" only when every
  A is above (or below) every B.

Per-episode outcomes within seeds get no interval of their own: where there are enough seeds for
one, the bootstrap over the seeds' means already carries the episodes' noise (each seed's mean
holds it), and resampling the episodes again inside each resampled seed would count that noise
twice (Davison & Hinkley 1997, section 3.8). So `two_level_interval` is gone; `pooled_rate` shows
the episodes' own uncertainty, and says it leaves out the seeds'.

Every interval carries the words that say what it is (`method`), so a report never shows a number
in brackets without its source.
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

CONFIDENCE = 0.95
REPS = 2000  # bootstrap resamples
# The one rule for every bootstrap over seeds here and in motorlab.stats: below 5 seeds a percentile
# bootstrap of a handful of values mostly returns their extremes, which is the range, not a 95% CI.
MIN_SEEDS_FOR_INTERVAL = 5
MIN_SEEDS_FOR_IQM = 4  # the IQM trims 25% at each end: with 3 values it trims nothing (it is the mean)


def too_few_seeds(n: int) -> str:
    return f"n = {n}: too few seeds for a confidence interval, which needs {MIN_SEEDS_FOR_INTERVAL}"


@contextlib.contextmanager
def fixed_rng():
    """rliable draws parts of its bootstrap from NumPy's global generator: seed it for the call (the
    same runs give the same interval), then put it back; arch warns about degenerate resamples."""
    state = np.random.get_state()
    np.random.seed(0)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        np.random.set_state(state)


@dataclass(frozen=True)
class SeedsSummary:
    """One number over seeds: the IQM or the mean; its 95% CI from MIN_SEEDS_FOR_INTERVAL seeds
    (None below, or where the seeds agree), and the seeds' range [min, max] from 2 seeds (None for
    one). `interval` is the one a text shows: the CI from 5 seeds, else the range."""

    values: tuple[float, ...]
    statistic: Literal["IQM", "mean"]
    value: float
    ci: tuple[float, float] | None
    range: tuple[float, float] | None = None

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def interval(self) -> tuple[float, float] | None:
        """The interval shown: the CI from MIN_SEEDS_FOR_INTERVAL seeds, else the seeds' range; None
        where it would be a point (one seed, or seeds that agree)."""
        shown = self.ci if self.n >= MIN_SEEDS_FOR_INTERVAL else self.range
        return shown if shown is not None and shown[1] > shown[0] else None

    @property
    def method(self) -> str:
        """What `interval` is, or why there is none."""
        n, need = self.n, MIN_SEEDS_FOR_INTERVAL
        if n == 1:
            return "one seed: no interval"
        if n >= need:
            if self.ci is not None:
                return f"95% stratified-bootstrap CI over {n} seeds"
            return f"no interval: the {n} seeds agree, and a bootstrap of them has no spread"
        if self.interval is not None:
            return f"range of {n} seeds, not a confidence interval: one needs {need} seeds"
        return f"the {n} seeds agree; no confidence interval below {need} seeds"

    def text(self, fmt=lambda v: f"{v:.3g}") -> str:
        """E.g. "IQM 0.61 [0.52, 0.70] (95% stratified-bootstrap CI over 5 seeds)", "mean 20% [10%, 30%]
        (range of 3 seeds, not a confidence interval: one needs 5 seeds)"."""
        if self.n == 1:
            return f"{fmt(self.value)} (one seed)"
        shown = self.interval
        interval = f" [{fmt(shown[0])}, {fmt(shown[1])}]" if shown else ""
        return f"{self.statistic} {fmt(self.value)}{interval} ({self.method})"

    def to_json(self) -> dict[str, Any]:
        return {"n": self.n, "values": list(self.values), "statistic": self.statistic, "value": self.value,
                "ci": list(self.ci) if self.ci else None, "range": list(self.range) if self.range else None,
                "method": self.method}


def across_seeds(values: list[float] | tuple[float, ...] | np.ndarray) -> SeedsSummary:
    """The IQM (>= MIN_SEEDS_FOR_IQM seeds) or the mean of per-seed values, with rliable's 95%
    stratified-bootstrap interval from MIN_SEEDS_FOR_INTERVAL seeds on (None below) and the seeds'
    range from 2 seeds."""
    from rliable import library as rly
    from rliable import metrics as rm

    x = np.asarray(values, dtype=np.float64).ravel()
    if len(x) == 0:
        raise ValueError("across_seeds needs at least one seed's value")
    if not np.isfinite(x).all():
        raise ValueError(f"across_seeds takes finite values, got {x.tolist()}")
    statistic: Literal["IQM", "mean"] = "IQM" if len(x) >= MIN_SEEDS_FOR_IQM else "mean"
    func = rm.aggregate_iqm if statistic == "IQM" else rm.aggregate_mean
    value = float(func(x[:, None]))
    ci = None
    if len(x) >= MIN_SEEDS_FOR_INTERVAL:
        with fixed_rng():
            _, intervals = rly.get_interval_estimates({"s": x[:, None]}, lambda s: np.array([func(s)]), reps=REPS,
                                                      confidence_interval_size=CONFIDENCE,
                                                      random_state=np.random.RandomState(0))
        low, high = float(intervals["s"][0, 0]), float(intervals["s"][1, 0])
        ci = (low, high) if high > low else None  # equal seeds: a point is no 95% interval
    spread = (float(x.min()), float(x.max())) if len(x) >= 2 else None
    return SeedsSummary(tuple(float(v) for v in x), statistic, value, ci, spread)


def wilson(k: int, n: int) -> tuple[float, float]:
    """The 95% Wilson score interval of the proportion k / n (scipy's binomtest), clipped to [0, 1]
    (its float ends may stray past them by a rounding error)."""
    from scipy.stats import binomtest

    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"{k} of {n} is no proportion")
    low, high = binomtest(int(k), int(n)).proportion_ci(confidence_level=CONFIDENCE, method="wilson")
    return max(0.0, float(low)), min(1.0, float(high))


@dataclass(frozen=True)
class PooledRate:
    """A success rate pooled over every seed's episodes, with its Wilson score interval."""

    successes: int
    episodes: int
    seeds: int
    ci: tuple[float, float]

    @property
    def rate(self) -> float:
        return self.successes / self.episodes

    @property
    def method(self) -> str:
        return f"95% Wilson interval over {self.episodes} episodes pooled from {self.seeds} seed(s)"

    def text(self, fmt=lambda v: f"{100 * v:.0f}%") -> str:
        return f"{fmt(self.rate)} [{fmt(self.ci[0])}, {fmt(self.ci[1])}] ({self.method})"

    def to_json(self) -> dict[str, Any]:
        return {"successes": self.successes, "episodes": self.episodes, "seeds": self.seeds, "rate": self.rate,
                "ci": list(self.ci), "method": self.method}


def pooled_rate(successes: list[int], episodes: list[int]) -> PooledRate:
    """Per seed: successes out of episodes; pooled, with the Wilson score interval (`wilson`).

    Pooling treats the episodes as one sample: it shows the episode-level uncertainty that a few
    seeds cannot, and says so in its method; it does not cover seed-to-seed variation (across_seeds'
    interval over the seeds' rates does, from MIN_SEEDS_FOR_INTERVAL seeds)."""
    if len(successes) != len(episodes) or not successes:
        raise ValueError("pooled_rate needs one success count and one episode count per seed")
    k, n = int(sum(successes)), int(sum(episodes))
    if n <= 0 or not 0 <= k <= n or any(not 0 <= s <= e for s, e in zip(successes, episodes)):
        raise ValueError(f"successes {successes} out of episodes {episodes} is no proportion")
    return PooledRate(k, n, len(successes), wilson(k, n))


Overlap = Literal["tied", "apart", "mixed"]


@dataclass(frozen=True)
class PBetter:
    """P(A > B): the probability that a run of A beats a run of B, with its interval where both sides
    have MIN_SEEDS_FOR_INTERVAL seeds. `overlap`: "tied" (every value of both sides the same),
    "apart" (every A above every B, or every A below), else "mixed"."""

    p: float
    ci: tuple[float, float] | None
    seeds: tuple[int, int]
    overlap: Overlap = "mixed"

    @property
    def method(self) -> str:
        a, b = self.seeds
        if self.overlap == "tied":
            return "all tied: every seed of both sides has the same value"
        if self.ci is not None:
            return f"95% stratified-bootstrap CI over {a} and {b} seeds"
        if min(self.seeds) < MIN_SEEDS_FOR_INTERVAL:
            return f"no interval: n = {a} and {b} seeds, too few for one, which needs {MIN_SEEDS_FOR_INTERVAL} a side"
        if self.overlap == "apart":
            return "no interval: the two sides' seeds do not overlap, so every bootstrap resample gives the same P"
        return "no interval: every bootstrap resample gives the same P"

    def text(self) -> str:
        interval = f" [{self.ci[0]:.2f}, {self.ci[1]:.2f}]" if self.ci else ""
        return f"P(A > B) = {self.p:.2f}{interval} ({self.method})"

    def to_json(self) -> dict[str, Any]:
        return {"p": self.p, "ci": list(self.ci) if self.ci else None, "seeds": list(self.seeds),
                "overlap": self.overlap, "method": self.method}


def _overlap(x: np.ndarray, y: np.ndarray) -> Overlap:
    if x.min() == x.max() == y.min() == y.max():
        return "tied"
    return "apart" if x.min() > y.max() or x.max() < y.min() else "mixed"


def p_better(a: list[float] | np.ndarray, b: list[float] | np.ndarray, higher_is_better: bool = True) -> PBetter:
    """rliable's probability of improvement of A over B (ties count half), per-seed values."""
    from rliable import library as rly
    from rliable import metrics as rm

    sign = 1.0 if higher_is_better else -1.0
    x, y = (sign * np.asarray(v, dtype=np.float64).ravel()[:, None] for v in (a, b))
    if not len(x) or not len(y):
        raise ValueError("p_better needs at least one seed on each side")
    overlap = _overlap(x, y)
    if overlap == "tied":  # every pair ties: P is one half by definition, and no resample changes it
        return PBetter(0.5, None, (len(x), len(y)), overlap)
    p = float(rm.probability_of_improvement(x, y))
    ci = None
    if min(len(x), len(y)) >= MIN_SEEDS_FOR_INTERVAL:
        with fixed_rng():
            _, intervals = rly.get_interval_estimates({"pair": (x, y)}, rm.probability_of_improvement, reps=REPS,
                                                      confidence_interval_size=CONFIDENCE,
                                                      random_state=np.random.RandomState(0))
        low, high = (float(v) for v in np.ravel(intervals["pair"]))
        ci = (low, high) if high > low else None  # seeds that do not overlap: a point is no 95% interval
    return PBetter(p, ci, (len(x), len(y)), overlap)
