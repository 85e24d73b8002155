"""Statistics across seeds: each metric per setting (motorlab.intervals: the IQM only from 4
seeds, a 95% stratified-bootstrap interval only from 5, the seeds' range below), the probability
of improvement between settings, and performance profiles (rliable, Agarwal et al., 2021).
Bootstraps use a fixed random state, so the same runs give the same numbers.

Steps to a threshold across seeds (`steps_to_threshold`, `steps_ratio`): a seed that never
reached the threshold within its budget is right-censored at that budget, and the seeds'
median is the Kaplan-Meier median (scipy.stats.ecdf on scipy.stats.CensoredData). k of n solved
has its 95% Wilson interval; the median and the ratio of two medians, from 5 seeds (a side), a 95%
percentile-bootstrap interval over the seeds, each resampled seed keeping its censoring."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal

import numpy as np

from motorlab.intervals import (
    CONFIDENCE,
    MIN_SEEDS_FOR_INTERVAL,
    across_seeds,
    fixed_rng,
    p_better,
    too_few_seeds,
    wilson,
)

REPS = 2000  # bootstrap resamples; rliable's CIs settle well before this for a handful of seeds
# metric -> higher is better; a study's metrics are "<step>.<metric>"
DIRECTION = {"final_return": True, "success_rate": True, "steps_to_success": False}
PROFILED = ("final_return", "success_rate")

Score = tuple[float, bool]  # (value, censored: steps_to_success of a run that never solved = its budget)


def _base(metric: str) -> str:
    return metric.rsplit(".", 1)[-1]


def _scores_of(summary: dict[str, Any], prefix: str, eval_prefix: str) -> dict[str, Score]:
    out: dict[str, Score] = {}
    for metric, keys in (("final_return", ("return_mean",)), ("success_rate", ("success_rate",))):
        for key in keys:
            value = summary.get(f"{prefix}{eval_prefix}{key}", summary.get(f"{prefix}{key}"))
            if isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value):
                out[metric] = (float(value), False)
    if f"{prefix}steps_to_success" in summary:
        steps = summary[f"{prefix}steps_to_success"]
        budget = summary.get(f"{prefix}timesteps")
        if steps is not None:
            out["steps_to_success"] = (float(steps), False)
        elif budget is not None:  # never solved: at least the budget (a lower bound), marked censored
            out["steps_to_success"] = (float(budget), True)
    return out


def trial_scores(summary: dict[str, Any]) -> dict[str, Score]:
    """Final return, success rate and steps-to-success of one finished trial: a run folder's
    summary.json, or a study's ("<step>.<metric>" for each step that has them)."""
    if "recipe" in summary and isinstance(summary.get("steps"), list):
        return {f"{step}.{m}": v for step in summary["steps"]
                for m, v in _scores_of(summary, f"{step}.", "").items()}
    return _scores_of(summary, "", "eval_")


def steps_of_scores(runs: list[Score]) -> StepsToThreshold:
    """Steps to success over seeds given as Scores: an unsolved seed censored at its budget (its
    recorded value); a solved seed's budget is not kept, so the largest value seen stands for it
    (it only says whether the seeds shared one)."""
    top = max(1, int(max(v for v, _ in runs)))
    return steps_to_threshold([None if censored else max(1, int(v)) for v, censored in runs],
                              [max(1, int(v)) if censored else top for v, censored in runs])


def _steps_entry(runs: list[Score]) -> dict[str, Any]:
    """Steps to success over seeds: k of n solved (with its Wilson interval) and the Kaplan-Meier
    median (with its bootstrap interval from 5 seeds), each unsolved seed censored at its budget
    (its recorded value), never counted as if it had solved there."""
    result = steps_of_scores(runs).to_json()
    keep = ("solved", "solved_ci", "median", "median_above", "median_ci", "median_ci_method", "text")
    return {"values": [v for v, _ in runs], "censored": [c for _, c in runs],
            "unsolved": result["seeds"] - result["solved"], **{k: result[k] for k in keep}}


def aggregate(scores: dict[str, list[dict[str, Score]]]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Each metric per setting over its seeds (motorlab.intervals): the mean, the IQM from 4 seeds,
    a 95% interval from 5 seeds where it has a width (the seeds' range below, in the details); steps
    to success as k of n solved (Wilson) with the Kaplan-Meier median (unsolved seeds censored at
    their budgets; its bootstrap interval from 5 seeds); the probability that one setting beats
    another, with its interval from 5 seeds a side; performance profiles of returns and success
    rates.

    Args:
        scores: setting label -> one dict of trial_scores per finished seed.

    Returns:
        (flat summary keys "<setting>.<metric>_mean", "_iqm" (4+ seeds), "_iqm_ci_low" and "_high"
        (5+ seeds, where the interval has a width), "steps_to_success_solved", "_median";
        details for plots and aggregate.json, each entry with the words that say what it is)
    """
    flat: dict[str, Any] = {}
    details: dict[str, Any] = {"metrics": {}, "probability_of_improvement": {}, "profiles": {}}
    # a study's steps in their recipe order; within each: return, success, steps
    seen = list(dict.fromkeys(m for runs in scores.values() for r in runs for m in r))
    steps = list(dict.fromkeys(m.rpartition(".")[0] for m in seen))
    names = sorted(seen, key=lambda m: (steps.index(m.rpartition(".")[0]), list(DIRECTION).index(_base(m))))
    per_metric: dict[str, dict[str, np.ndarray]] = {}
    for metric in names:
        runs = {s: [r[metric] for r in rs if metric in r] for s, rs in scores.items()}
        runs = {s: v for s, v in runs.items() if v}
        values = {s: np.array([[v] for v, _ in rs]) for s, rs in runs.items()}
        per_metric[metric] = values
        details["metrics"][metric] = {}
        for s, rs in runs.items():
            if _base(metric) == "steps_to_success":
                entry = _steps_entry(rs)
                flat.update({f"{s}.{metric}_solved": entry["solved"], f"{s}.{metric}_unsolved": entry["unsolved"],
                             f"{s}.{metric}_median": entry["median"]})
            else:
                summary = across_seeds([v for v, _ in rs])
                key = "iqm" if summary.statistic == "IQM" else "mean"
                entry = {**summary.to_json(), "mean": float(np.mean([v for v, _ in rs]))}
                flat[f"{s}.{metric}_mean"] = entry["mean"]
                if key == "iqm":
                    flat[f"{s}.{metric}_iqm"] = summary.value
                if summary.ci:
                    flat[f"{s}.{metric}_{key}_ci_low"], flat[f"{s}.{metric}_{key}_ci_high"] = summary.ci
            details["metrics"][metric][s] = entry
        for a, b in itertools.combinations(values, 2):
            better = p_better(values[a], values[b], higher_is_better=DIRECTION[_base(metric)])
            details["probability_of_improvement"].setdefault(metric, []).append({"a": a, "b": b, **better.to_json()})
            flat[f"{a}.{metric}_p_better_than[{b}]"] = better.p
    for metric, values in per_metric.items():
        if _base(metric) in PROFILED and values:
            details["profiles"][metric] = _profile(values)
    for s, runs in scores.items():
        flat[f"{s}.seeds"] = len(runs)
    return flat, details


def _profile(values: dict[str, np.ndarray]) -> dict[str, Any]:
    """Fraction of runs scoring above tau, for taus across the observed range (rliable's score
    distribution), with its bootstrap band where every setting has MIN_SEEDS_FOR_INTERVAL seeds."""
    from rliable import library as rly

    every = np.concatenate([v[:, 0] for v in values.values()])
    lo, hi = float(every.min()), float(every.max())
    taus = np.linspace(lo - 1e-9, hi + 1e-9 if hi > lo else lo + 1.0, 51)
    banded = min(len(v) for v in values.values()) >= MIN_SEEDS_FOR_INTERVAL  # else no band, as no interval
    with fixed_rng():
        point, ci = rly.create_performance_profile(values, taus, reps=REPS if banded else 1)
    if not banded:
        ci = {s: np.stack([p, p]) for s, p in point.items()}
    return {"tau": taus.tolist(), **{s: {"fraction": point[s].tolist(), "low": ci[s][0].tolist(),
                                         "high": ci[s][1].tolist()} for s in values}}


# ---- steps to a threshold: censored at each seed's budget, Kaplan-Meier median ----------------

_HALF = 0.5 - 1e-9  # the KM estimate is a product of fractions: 1 - (3/4)(2/3) may land a hair under 0.5
_TAIL = (1 - CONFIDENCE) / 2


@dataclass(frozen=True)
class SeedSteps:
    """One seed: the env steps at which it first reached the threshold, and its budget."""

    steps: int | None  # None: never reached (as given; a number above the budget is kept, and censored)
    budget: int  # the env steps this seed was allowed
    censored: bool  # not reached within the budget: right-censored at `budget`

    @property
    def time(self) -> int:
        """The seed's time for Kaplan-Meier: its steps if reached within the budget, else the budget."""
        return self.budget if self.censored else int(self.steps)  # type: ignore[arg-type]


@dataclass(frozen=True)
class MedianInterval:
    """The 95% percentile-bootstrap interval of a Kaplan-Meier median over seeds. A resample whose
    median is censored (fewer than half its seeds reached the threshold) counts as +inf: an end that
    falls on such resamples is only known to be above `above`, and is None here ("> above")."""

    low: float | None  # None: above `above` too (the median is censored in nearly every resample)
    high: float | None  # None: above `above` (the median is censored in more than 2.5% of resamples)
    above: int | None  # what a censored end is above: the least of the censored resamples' largest times
    # (the budget, where the seeds share one); None where no resample is censored
    seeds: int

    @property
    def method(self) -> str:
        return f"95% bootstrap CI over {self.seeds} seeds"

    def text(self) -> str:
        """E.g. "[1,000, > 3,000]"."""
        def end(v: float | None) -> str:
            return f"> {self.above:,}" if v is None else f"{v:,.0f}"
        return f"[{end(self.low)}, {end(self.high)}]"

    def to_json(self) -> dict[str, Any]:
        return {"low": self.low, "high": self.high, "low_above_budget": self.low is None,
                "high_above_budget": self.high is None, "above": self.above, "method": self.method}


@dataclass(frozen=True)
class StepsToThreshold:
    """Env steps to reach a threshold over seeds, each seed right-censored at its own budget.

    `median` is the Kaplan-Meier median: the smallest time at which the KM estimate of the CDF
    (the fraction of seeds that have reached the threshold, censored seeds leaving the risk set at
    their budgets) reaches 0.5. It is None when the estimate stays below 0.5 at every observed
    time: the median is then above `median_above`, the largest observed time (the budget, when
    all seeds share one). With ties the smallest such time is taken: seeds at [1000, 1000, 2000,
    2000] have median 1000 (the estimate is 0.5 at 1000), where numpy's median says 1500. With
    every seed solved it is the ordinary lower median of the steps.

    Intervals: `solved_ci`, the 95% Wilson interval of the share solved (k of n); `median_ci`, from
    MIN_SEEDS_FOR_INTERVAL seeds, the median's bootstrap interval (`MedianInterval`, see
    `_median_draws`), None below."""

    per_seed: tuple[SeedSteps, ...]
    median: float | None

    @property
    def seeds(self) -> int:
        """n: the seeds."""
        return len(self.per_seed)

    @property
    def solved(self) -> int:
        """k: the seeds that reached the threshold within their budgets."""
        return sum(not s.censored for s in self.per_seed)

    @property
    def solved_ci(self) -> tuple[float, float]:
        """The 95% Wilson interval of the share of seeds that solve (k of n)."""
        return wilson(self.solved, self.seeds)

    @property
    def budgets(self) -> tuple[int, ...]:
        return tuple(s.budget for s in self.per_seed)

    @property
    def budget(self) -> int:
        """The largest budget (the common one when the seeds share it)."""
        return max(self.budgets)

    @property
    def median_above(self) -> int | None:
        """When `median` is None: the median is above this (the largest observed time); else None."""
        return None if self.median is not None else max(s.time for s in self.per_seed)

    @cached_property
    def median_ci(self) -> MedianInterval | None:
        """The median's 95% bootstrap interval over the seeds, from MIN_SEEDS_FOR_INTERVAL seeds;
        computed once, on first use, with a fixed seed (the same runs give the same interval)."""
        if self.seeds < MIN_SEEDS_FOR_INTERVAL:
            return None
        medians, largest = _median_draws(self.per_seed)
        low, high = np.quantile(medians, [_TAIL, 1 - _TAIL], method="inverted_cdf")  # a draw each: inf stays inf
        censored = np.isinf(medians)
        above = int(largest[censored].min()) if censored.any() else None
        return MedianInterval(*(None if math.isinf(v) else float(v) for v in (low, high)), above, self.seeds)

    @property
    def median_ci_method(self) -> str:
        """What the median's interval is, or why there is none."""
        return self.median_ci.method if self.median_ci else f"no interval ({too_few_seeds(self.seeds)})"

    @property
    def text(self) -> str:
        """E.g. "3 of 5 seeds, 95% Wilson interval [23%, 88%]; median 1,400 steps (Kaplan–Meier), 95%
        bootstrap CI over 5 seeds [1,000, > 3,000]", "1 of 3 seeds, 95% Wilson interval [6%, 79%];
        median > 3,000 (budget), no interval (n = 3: too few seeds ...)"."""
        low, high = self.solved_ci
        head = f"{self.solved} of {self.seeds} seeds, 95% Wilson interval [{low:.0%}, {high:.0%}]"
        if self.median is not None:
            median = f"median {self.median:,.0f} steps (Kaplan–Meier)"
        else:
            shared = len(set(self.budgets)) == 1
            median = f"median > {self.median_above:,} ({'budget' if shared else 'the largest budget'})"
        ci = f"{self.median_ci.method} {self.median_ci.text()}" if self.median_ci else self.median_ci_method
        return f"{head}; {median}, {ci}"

    def at_most(self, steps: float) -> bool | None:
        """Is the median at most `steps`? None where the censoring leaves it open (fewer than half
        solved within a budget below `steps`: the median is above the budget, where is unknown)."""
        if self.median is not None:
            return self.median <= steps
        return False if self.median_above >= steps else None

    def to_json(self) -> dict[str, Any]:
        """Every number, for a results file."""
        return {"solved": self.solved, "seeds": self.seeds, "solved_ci": list(self.solved_ci),
                "solved_ci_method": "95% Wilson interval", "budgets": list(self.budgets),
                "median": self.median, "median_above": self.median_above,
                "median_ci": self.median_ci.to_json() if self.median_ci else None,
                "median_ci_method": self.median_ci_method, "text": self.text,
                "per_seed": [{"steps": s.steps, "budget": s.budget, "censored": s.censored} for s in self.per_seed]}


def steps_to_threshold(steps: list[int | None], budgets: list[int] | int) -> StepsToThreshold:
    """Steps to a threshold over seeds, with their Kaplan-Meier median (see `StepsToThreshold`).

    Args:
        steps: per seed, the env steps at which the threshold was first reached; None if it never
            was. A seed that never reached it is right-censored at its budget, never at the steps
            it happened to collect; a number above the seed's budget (a loop whose last round went
            past it) is no hit within the budget and is censored at the budget too.
        budgets: each seed's budget of env steps, or one budget for every seed.
    """
    n = len(steps)
    if n == 0:
        raise ValueError("steps_to_threshold needs at least one seed")
    per_budget = [budgets] * n if isinstance(budgets, int) else list(budgets)
    if len(per_budget) != n:
        raise ValueError(f"{n} seeds but {len(per_budget)} budgets")
    if any(b <= 0 for b in per_budget) or any(s is not None and s <= 0 for s in steps):
        raise ValueError("steps and budgets are positive numbers of env steps")
    per_seed = tuple(SeedSteps(s, int(b), s is None or s > b) for s, b in zip(steps, per_budget))
    return StepsToThreshold(per_seed, _km_median(per_seed))


def steps_to_success(steps: list[int | None], ran: list[int]) -> StepsToThreshold:
    """Steps to success over training runs: each run's budget is the env steps it ran (at least its
    steps to success: the last rollout may end past `timesteps`), so an unsolved run is censored
    where it stopped. The one rule for a study's finding, a step's aggregate and any headline."""
    return steps_to_threshold(steps, [max(r, s or 0, 1) for r, s in zip(ran, steps, strict=True)])


def _km_median(per_seed: tuple[SeedSteps, ...]) -> float | None:
    from scipy.stats import CensoredData, ecdf

    solved = [s.time for s in per_seed if not s.censored]
    if not solved:  # nothing to estimate: the CDF is 0 up to the largest budget
        return None
    data = CensoredData(uncensored=solved, right=[s.time for s in per_seed if s.censored])
    cdf = ecdf(data).cdf  # a step function: probabilities[i] from quantiles[i] on
    reached = np.flatnonzero(cdf.probabilities >= _HALF)
    return float(cdf.quantiles[reached[0]]) if len(reached) else None


def _median_draws(per_seed: tuple[SeedSteps, ...], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """REPS bootstrap resamples of the seeds, each seed drawn with its censoring: per resample its
    Kaplan-Meier median (`_km_median`; +inf where censored, i.e. above the resample's largest time)
    and its largest observed time. A fixed seed: the same runs give the same draws."""
    rng = np.random.default_rng(seed)
    picks = rng.integers(len(per_seed), size=(REPS, len(per_seed)))
    times = np.array([s.time for s in per_seed], dtype=np.int64)
    # the median depends only on the resample's multiset of (time, censored): 5 seeds have at most 126
    keys = np.sort((2 * times + [s.censored for s in per_seed])[picks], axis=1)
    memo: dict[bytes, float] = {}
    medians = np.empty(REPS)
    for r, (row, key) in enumerate(zip(picks, keys)):
        k = key.tobytes()
        if k not in memo:
            median = _km_median(tuple(per_seed[i] for i in row))
            memo[k] = math.inf if median is None else median
        medians[r] = memo[k]
    return medians, times[picks].max(axis=1).astype(np.float64)


@dataclass(frozen=True)
class RatioInterval:
    """The 95% bootstrap interval of a ratio of Kaplan-Meier medians (see `steps_ratio`). `low` 0: open
    below (a's median censored in more than 2.5% of resamples); `high` inf: open above (b's)."""

    low: float
    high: float
    seeds: tuple[int, int]

    @property
    def method(self) -> str:
        return f"95% bootstrap CI over {self.seeds[0]} and {self.seeds[1]} seeds"

    def text(self) -> str:
        """E.g. "[6.1, 12.5]"; an open end as an open bracket: "[6.1, ∞)", "(0, 2.4]" (the ratio is only
        known to be below 2.4), "(0, ∞)": a reader sees a bound, not a measured 0."""
        low = "(0" if self.low == 0 else f"[{self.low:.3g}"
        high = "∞)" if math.isinf(self.high) else f"{self.high:.3g}]"
        return f"{low}, {high}"

    def to_json(self) -> dict[str, Any]:
        return {"low": self.low, "high": None if math.isinf(self.high) else self.high,
                "low_open": self.low == 0, "high_open": math.isinf(self.high), "method": self.method}


@dataclass(frozen=True)
class StepsRatio:
    """b's median steps over a's (e.g. a = the loop, b = SAC: how many times more steps SAC needs).

    bound:
      exact:   both medians are known; ratio = b.median / a.median.
      lower:   b's median is censored (above b.median_above, its budget): the ratio is above
               ratio = b.median_above / a.median.
      upper:   a's median is censored (above a.median_above): the ratio is below
               ratio = b.median / a.median_above.
      unknown: both censored: ratio is None.

    ci: from MIN_SEEDS_FOR_INTERVAL seeds a side, the 95% bootstrap interval (`steps_ratio`); None below.
    """

    ratio: float | None
    bound: Literal["exact", "lower", "upper", "unknown"]
    numerator: float | None  # b's median, or b's budget where censored (lower); None when unknown
    denominator: float | None  # a's median, or a's budget where censored (upper); None when unknown
    ci: RatioInterval | None = None
    seeds: tuple[int, int] = (0, 0)  # a's and b's

    @property
    def ci_method(self) -> str:
        """What the interval is, or why there is none."""
        if self.ci is not None:
            return self.ci.method
        a, b = self.seeds
        return f"no interval: n = {a} and {b} seeds, too few for one, which needs {MIN_SEEDS_FOR_INTERVAL} a side"

    @property
    def text(self) -> str:
        """E.g. "= 6, 95% bootstrap CI over 5 and 5 seeds [4, ∞)", "> 30, no interval: ..."."""
        sign = {"exact": "=", "lower": ">", "upper": "<"}.get(self.bound)
        point = "unknown (both medians censored)" if sign is None else f"{sign} {self.ratio:.3g}"
        return f"{point}, {self.ci.method} {self.ci.text()}" if self.ci else f"{point}, {self.ci_method}"

    def at_most(self, value: float) -> bool | None:
        """Is the ratio at most `value`? None where its bound leaves that open."""
        if self.bound == "exact":
            return self.ratio <= value
        if self.bound == "upper":  # ratio < self.ratio
            return True if self.ratio <= value else None
        if self.bound == "lower":  # ratio > self.ratio
            return False if self.ratio >= value else None
        return None

    def to_json(self) -> dict[str, Any]:
        return {"ratio": self.ratio, "bound": self.bound, "numerator": self.numerator,
                "denominator": self.denominator, "ci": self.ci.to_json() if self.ci else None,
                "ci_method": self.ci_method, "text": self.text}


def steps_ratio(a: StepsToThreshold, b: StepsToThreshold) -> StepsRatio:
    """The ratio of medians b / a, what kind of number it is (see `StepsRatio`), and from
    MIN_SEEDS_FOR_INTERVAL seeds a side its 95% bootstrap interval (`_ratio_interval`)."""
    ci = _ratio_interval(a, b) if min(a.seeds, b.seeds) >= MIN_SEEDS_FOR_INTERVAL else None
    seeds = (a.seeds, b.seeds)
    if a.median is not None and b.median is not None:
        return StepsRatio(b.median / a.median, "exact", b.median, a.median, ci, seeds)
    if a.median is not None:  # b censored: its median > its budget, so the ratio > budget / a's median
        return StepsRatio(b.median_above / a.median, "lower", float(b.median_above), a.median, ci, seeds)
    if b.median is not None:  # a censored: the ratio < b's median / a's budget
        return StepsRatio(b.median / a.median_above, "upper", b.median, float(a.median_above), ci, seeds)
    return StepsRatio(None, "unknown", None, None, ci, seeds)


def _ratio_interval(a: StepsToThreshold, b: StepsToThreshold) -> RatioInterval:
    """The 95% percentile-bootstrap interval of b.median / a.median: each side's seeds resampled on
    their own (`_median_draws`, different fixed seeds), one ratio per pair of resamples.

    Censoring propagates as bounds. In a resample where b's median is censored (above b's largest
    time there) the ratio is only known to be above largest_b / median_a; where a's is censored, only
    below median_b / largest_a (above 0); both censored: anywhere in (0, inf). So every resample
    gives a range [lo, hi] (a point where both medians are known), and the interval takes its low
    end from the lo's and its high end from the hi's: it holds whatever the censored medians are.
    A censored b in more than 2.5% of resamples leaves the high end open (inf); a censored a, the
    low end (0)."""
    med_a, largest_a = _median_draws(a.per_seed, seed=0)
    med_b, largest_b = _median_draws(b.per_seed, seed=1)
    known_a, known_b = np.isfinite(med_a), np.isfinite(med_b)
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.where(known_a, np.where(known_b, med_b, largest_b) / med_a, 0.0)
        hi = np.where(known_b, med_b / np.where(known_a, med_a, largest_a), math.inf)
    low = float(np.quantile(lo, _TAIL, method="inverted_cdf"))
    high = float(np.quantile(hi, 1 - _TAIL, method="inverted_cdf"))
    return RatioInterval(low, high, (a.seeds, b.seeds))
