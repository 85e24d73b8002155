"""Statistics across seeds: each metric per setting (motorlab.intervals: the IQM only from 4
seeds, a 95% stratified-bootstrap interval only from 3), the probability of improvement between
settings, and performance profiles (rliable, Agarwal et al., 2021). Bootstraps use a fixed random
state, so the same runs give the same numbers.

Steps to a threshold across seeds (`steps_to_threshold`, `steps_ratio`): a seed that never
reached the threshold within its budget is right-censored at that budget, and the seeds'
median is the Kaplan-Meier median (scipy.stats.ecdf on scipy.stats.CensoredData)."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from motorlab.intervals import MIN_SEEDS_FOR_INTERVAL, across_seeds, fixed_rng, p_better

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
    """Steps to success over seeds: k of n solved and the Kaplan-Meier median, each unsolved seed
    censored at its budget (its recorded value), never counted as if it had solved there."""
    result = steps_of_scores(runs)
    return {"values": [v for v, _ in runs], "censored": [c for _, c in runs], "solved": result.solved,
            "unsolved": result.seeds - result.solved, "median": result.median, "median_above": result.median_above,
            "text": result.text}


def aggregate(scores: dict[str, list[dict[str, Score]]]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Each metric per setting over its seeds (motorlab.intervals): the mean, the IQM from 4 seeds,
    a 95% interval from 3 seeds where it has a width; steps to success as k of n solved with the
    Kaplan-Meier median (unsolved seeds censored at their budgets); the probability that one
    setting beats another, with its interval from 3 seeds a side; performance profiles of returns
    and success rates.

    Args:
        scores: setting label -> one dict of trial_scores per finished seed.

    Returns:
        (flat summary keys "<setting>.<metric>_mean", "_iqm" (4+ seeds), "_mean_ci_low"/"_iqm_ci_low"
        and "_high" (whichever statistic the interval is of), "steps_to_success_solved", "_median";
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
    distribution), with its bootstrap band where every setting has 3 seeds or more."""
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
class StepsToThreshold:
    """Env steps to reach a threshold over seeds, each seed right-censored at its own budget.

    `median` is the Kaplan-Meier median: the smallest time at which the KM estimate of the CDF
    (the fraction of seeds that have reached the threshold, censored seeds leaving the risk set at
    their budgets) reaches 0.5. It is None when the estimate stays below 0.5 at every observed
    time: the median is then above `median_above`, the largest observed time (the budget, when
    all seeds share one). With ties the smallest such time is taken: seeds at [1000, 1000, 2000,
    2000] have median 1000 (the estimate is 0.5 at 1000), where numpy's median says 1500. With
    every seed solved it is the ordinary lower median of the steps."""

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

    @property
    def text(self) -> str:
        """E.g. "3 of 5 seeds; median 1,400 steps (Kaplan–Meier)", "1 of 5 seeds; median > 3,000 (budget)"."""
        head = f"{self.solved} of {self.seeds} seeds"
        if self.median is not None:
            return f"{head}; median {self.median:,.0f} steps (Kaplan–Meier)"
        shared = len(set(self.budgets)) == 1
        return f"{head}; median > {self.median_above:,} ({'budget' if shared else 'the largest budget'})"

    def at_most(self, steps: float) -> bool | None:
        """Is the median at most `steps`? None where the censoring leaves it open (fewer than half
        solved within a budget below `steps`: the median is above the budget, where is unknown)."""
        if self.median is not None:
            return self.median <= steps
        return False if self.median_above >= steps else None

    def to_json(self) -> dict[str, Any]:
        """Every number, for a results file."""
        return {"solved": self.solved, "seeds": self.seeds, "budgets": list(self.budgets),
                "median": self.median, "median_above": self.median_above, "text": self.text,
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
    """

    ratio: float | None
    bound: Literal["exact", "lower", "upper", "unknown"]
    numerator: float | None  # b's median, or b's budget where censored (lower); None when unknown
    denominator: float | None  # a's median, or a's budget where censored (upper); None when unknown

    @property
    def text(self) -> str:
        sign = {"exact": "=", "lower": ">", "upper": "<"}.get(self.bound)
        return "unknown (both medians censored)" if sign is None else f"{sign} {self.ratio:.3g}"

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
                "denominator": self.denominator, "text": self.text}


def steps_ratio(a: StepsToThreshold, b: StepsToThreshold) -> StepsRatio:
    """The ratio of medians b / a, and what kind of number it is (see `StepsRatio`)."""
    if a.median is not None and b.median is not None:
        return StepsRatio(b.median / a.median, "exact", b.median, a.median)
    if a.median is not None:  # b censored: its median > its budget, so the ratio > budget / a's median
        return StepsRatio(b.median_above / a.median, "lower", float(b.median_above), a.median)
    if b.median is not None:  # a censored: the ratio < b's median / a's budget
        return StepsRatio(b.median / a.median_above, "upper", b.median, float(a.median_above))
    return StepsRatio(None, "unknown", None, None)
