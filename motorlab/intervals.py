"""Intervals that claim no more than the seeds and episodes show.

- **Across seeds** (`across_seeds`): the IQM only where it trims something (>= 4 seeds; rliable's
  IQM of 3 values is their mean), else the mean, named as such; a 95% stratified-bootstrap interval
  (rliable) only from 3 seeds on, and only where it has a width. With 1-2 seeds the bootstrap can
  only return the lowest and highest seed, or a point, so no interval is given and the text says
  why; the same where the seeds agree.
- **Episodes pooled over seeds** (`pooled_rate`): a success rate from k of n episodes, with scipy's
  Wilson score interval for a binomial proportion.
- **Episodes within seeds** (`two_level_interval`): where each seed's per-episode outcomes exist,
  a two-level bootstrap: resample the seeds, then the episodes within each resampled seed.
- **P(A > B)** (`p_better`): rliable's probability of improvement, with its interval from 3 seeds
  per side, else a note that there are too few.

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
MIN_SEEDS_FOR_INTERVAL = 3  # below: the bootstrap's "interval" is the seeds' own range, or a point
MIN_SEEDS_FOR_IQM = 4  # the IQM trims 25% at each end: with 3 values it trims nothing (it is the mean)


def too_few_seeds(n: int) -> str:
    return f"n = {n}: too few seeds for an interval"


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
    """One number over seeds: the IQM or the mean, and its 95% interval where the seeds allow one."""

    values: tuple[float, ...]
    statistic: Literal["IQM", "mean"]
    value: float
    ci: tuple[float, float] | None

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def method(self) -> str:
        """What the interval is, or why there is none."""
        if self.ci is not None:
            return f"95% stratified-bootstrap CI over {self.n} seeds"
        if self.n < MIN_SEEDS_FOR_INTERVAL:
            return too_few_seeds(self.n)
        return f"no interval: the {self.n} seeds agree, and a bootstrap of them has no spread"

    def text(self, fmt=lambda v: f"{v:.3g}") -> str:
        """E.g. "IQM 0.61 [0.52, 0.70] (95% stratified-bootstrap CI over 5 seeds)", "mean 20% (n = 2:
        too few seeds for an interval)"."""
        if self.n == 1:
            return f"{fmt(self.value)} (one seed)"
        interval = f" [{fmt(self.ci[0])}, {fmt(self.ci[1])}]" if self.ci else ""
        return f"{self.statistic} {fmt(self.value)}{interval} ({self.method})"

    def to_json(self) -> dict[str, Any]:
        return {"n": self.n, "values": list(self.values), "statistic": self.statistic, "value": self.value,
                "ci": list(self.ci) if self.ci else None, "method": self.method}


def across_seeds(values: list[float] | tuple[float, ...] | np.ndarray) -> SeedsSummary:
    """The IQM (>= MIN_SEEDS_FOR_IQM seeds) or the mean of per-seed values, with rliable's 95%
    stratified-bootstrap interval from MIN_SEEDS_FOR_INTERVAL seeds on (None below)."""
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
    return SeedsSummary(tuple(float(v) for v in x), statistic, value, ci)


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
    """Per seed: successes out of episodes; pooled, with scipy's Wilson score interval (95%).

    Pooling treats the episodes as one sample: it shows the episode-level uncertainty that a few
    seeds cannot, and says so in its method; it does not cover seed-to-seed variation
    (`two_level_interval` does, where the episodes are at hand)."""
    from scipy.stats import binomtest

    if len(successes) != len(episodes) or not successes:
        raise ValueError("pooled_rate needs one success count and one episode count per seed")
    k, n = int(sum(successes)), int(sum(episodes))
    if n <= 0 or not 0 <= k <= n or any(not 0 <= s <= e for s, e in zip(successes, episodes)):
        raise ValueError(f"successes {successes} out of episodes {episodes} is no proportion")
    low, high = binomtest(k, n).proportion_ci(confidence_level=CONFIDENCE, method="wilson")
    return PooledRate(k, n, len(successes), (float(low), float(high)))


def two_level_interval(per_seed: list[list[float]] | list[np.ndarray], reps: int = REPS,
                       seed: int = 0) -> tuple[float, tuple[float, float]]:
    """The mean over seeds of each seed's mean outcome, and its 95% percentile interval from a
    two-level bootstrap: draw the seeds with replacement, then each drawn seed's episodes with
    replacement.

    Hand-written: rliable, arch and scipy.stats.bootstrap resample one level (runs, or rows); none
    resamples episodes nested in seeds. Needs >= MIN_SEEDS_FOR_INTERVAL seeds, for the same reason
    as `across_seeds`."""
    seeds = [np.asarray(e, dtype=np.float64).ravel() for e in per_seed]
    if len(seeds) < MIN_SEEDS_FOR_INTERVAL:
        raise ValueError(f"{too_few_seeds(len(seeds))} (a two-level bootstrap resamples the seeds too)")
    if any(len(e) == 0 for e in seeds):
        raise ValueError("every seed needs at least one episode")
    rng = np.random.default_rng(seed)
    point = float(np.mean([e.mean() for e in seeds]))
    draws = np.empty(reps)
    for r in range(reps):
        picked = rng.integers(len(seeds), size=len(seeds))
        draws[r] = np.mean([rng.choice(seeds[i], size=len(seeds[i])).mean() for i in picked])
    tail = (1 - CONFIDENCE) / 2
    return point, (float(np.quantile(draws, tail)), float(np.quantile(draws, 1 - tail)))


@dataclass(frozen=True)
class PBetter:
    """P(A > B): the probability that a run of A beats a run of B, with its interval where both sides
    have MIN_SEEDS_FOR_INTERVAL seeds."""

    p: float
    ci: tuple[float, float] | None
    seeds: tuple[int, int]

    @property
    def method(self) -> str:
        if self.ci is not None:
            return f"95% stratified-bootstrap CI over {self.seeds[0]} and {self.seeds[1]} seeds"
        if min(self.seeds) < MIN_SEEDS_FOR_INTERVAL:
            return f"no interval: n = {self.seeds[0]} and {self.seeds[1]} seeds (too few for one)"
        return "no interval: every bootstrap resample gives the same P (the two sides' seeds do not overlap)"

    def text(self) -> str:
        interval = f" [{self.ci[0]:.2f}, {self.ci[1]:.2f}]" if self.ci else ""
        return f"P(A > B) = {self.p:.2f}{interval} ({self.method})"

    def to_json(self) -> dict[str, Any]:
        return {"p": self.p, "ci": list(self.ci) if self.ci else None, "seeds": list(self.seeds),
                "method": self.method}


def p_better(a: list[float] | np.ndarray, b: list[float] | np.ndarray, higher_is_better: bool = True) -> PBetter:
    """rliable's probability of improvement of A over B (ties count half), per-seed values."""
    from rliable import library as rly
    from rliable import metrics as rm

    sign = 1.0 if higher_is_better else -1.0
    x, y = (sign * np.asarray(v, dtype=np.float64).ravel()[:, None] for v in (a, b))
    if not len(x) or not len(y):
        raise ValueError("p_better needs at least one seed on each side")
    p = float(rm.probability_of_improvement(x, y))
    ci = None
    if min(len(x), len(y)) >= MIN_SEEDS_FOR_INTERVAL:
        with fixed_rng():
            _, intervals = rly.get_interval_estimates({"pair": (x, y)}, rm.probability_of_improvement, reps=REPS,
                                                      confidence_interval_size=CONFIDENCE,
                                                      random_state=np.random.RandomState(0))
        low, high = (float(v) for v in np.ravel(intervals["pair"]))
        ci = (low, high) if high > low else None  # seeds that do not overlap: a point is no 95% interval
    return PBetter(p, ci, (len(x), len(y)))
