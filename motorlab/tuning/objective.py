"""The number a tuning trial is judged by: one per seed from its run's summary.json, and,
while the seeds still train, the intermediate numbers a pruner compares.

Intermediate numbers are reported at fixed env steps (every `report_every`), never at
whatever step a poll happened to see, so that a pruner compares trials at the same step:

- steps_to_success (minimized): at step t, each seed's steps restricted to t: t if it has not
  solved by t, else its steps-to-success. A trial that solved early keeps its value for every
  later step, so a slower trial is compared against it there.

A trial's seeds give one number (`Objective.combine`): for steps_to_success their restricted mean
(each seed's steps, an unsolved seed's budget), which is what the search compares. People read it
as "k of n seeds; median ..." with unsolved seeds censored at their budgets (`Objective.describe`),
never the budget shown as if a seed had solved there.
- final_return, success_rate: the latest evaluation's return (success rate) at or before t,
  from metrics.csv (the evaluations training already makes); a finished seed keeps its last.
- any other key: no intermediate numbers (nothing to prune on).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.intervals import MIN_SEEDS_FOR_IQM
from motorlab.runs import SUMMARY, is_complete, last_timesteps, read_config, read_json, read_metrics
from motorlab.stats import DIRECTION, Score, steps_of_scores, trial_scores

EVAL_COLUMN = {"final_return": "eval_return_mean", "success_rate": "eval_success_rate"}


def _base(key: str) -> str:
    return key.rpartition(".")[2]


@dataclass(frozen=True)
class Objective:
    """What a trial's seeds are scored by, and which way is better."""

    key: str
    maximize: bool

    @classmethod
    def make(cls, key: str, direction: str | None) -> Objective:
        """`direction` max or min; None: the metric's own (steps down, returns and success up; up otherwise).

        Raises:
            MotorlabError: a direction other than max or min.
        """
        if direction is None:
            return cls(key, DIRECTION.get(_base(key), True))
        if direction not in ("max", "min"):
            raise MotorlabError(f"--direction {direction!r}: give max or min.")
        return cls(key, direction == "max")

    @property
    def direction(self) -> str:
        return "maximize" if self.maximize else "minimize"

    @property
    def prunable(self) -> bool:
        """Training reports numbers this objective can be judged by before the end."""
        return _base(self.key) in (*EVAL_COLUMN, "steps_to_success")

    @property
    def censors(self) -> bool:
        """A seed may have no value, only a lower bound: steps_to_success of a run that never solved."""
        return _base(self.key) == "steps_to_success"

    def score(self, summary: dict[str, Any]) -> Score:
        """One seed's number, and whether it is censored: steps_to_success of a run that never
        solved is its budget (the least it would have needed), marked censored.

        Raises:
            MotorlabError: the summary has no such number (one line listing the keys it has).
        """
        scores = trial_scores(summary)
        if self.key in scores:
            if self.censors and scores[self.key][1]:
                prefix = self.key[: -len("steps_to_success")]
                budget = summary.get(f"{prefix}budget")
                if isinstance(budget, (int, float)):
                    return float(budget), True
            return scores[self.key]
        value = summary.get(self.key)
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value), False
        keys = sorted({*scores, *(k for k, v in summary.items() if isinstance(v, (int, float))
                                  and not isinstance(v, bool))})
        raise MotorlabError(f"--objective {self.key}: the runs' summary.json has no number {self.key!r}; "
                            f"numbers it has: {', '.join(keys)}.")

    def value(self, summary: dict[str, Any]) -> float:
        """One seed's number (a censored one at its budget: see `score`)."""
        return self.score(summary)[0]

    def statistic(self, n: int) -> str:
        """What `combine` computes over n seeds."""
        if self.censors:
            return "restricted mean"
        return "IQM" if n >= MIN_SEEDS_FOR_IQM else "mean"

    def combine(self, values: list[float]) -> float:
        """A trial's number over its seeds, the one the search compares.

        steps_to_success: the restricted mean, each seed's min(steps, budget) averaged (the area
        under the seeds' censored curve up to the budget: survival analysis's restricted mean).
        It needs no guess of what an unsolved seed would have needed and ranks a trial that
        solves more seeds, or sooner, lower. Otherwise the IQM from 4 seeds, else the mean
        (motorlab.intervals' rule)."""
        return float(np.mean(values)) if self.censors else iqm(values)

    def reached(self, scores: list[Score]):
        """Steps to success over the seeds (motorlab.stats.StepsToThreshold): k of n solved and
        their Kaplan-Meier median, each unsolved seed censored at its budget."""
        return steps_of_scores(scores)

    def describe(self, scores: list[Score], fmt: Callable[[float], str]) -> str:
        """A trial's seeds as people read them: "2 of 3 seeds; median 1,200 steps (Kaplan–Meier);
        restricted mean 1,900" for steps to success, else "IQM 812.3"."""
        together = f"{self.statistic(len(scores))} {fmt(self.combine([v for v, _ in scores]))}"
        return f"{self.reached(scores).text}; {together}" if self.censors else together

    @staticmethod
    def seed_text(score: Score, fmt: Callable[[float], str]) -> str:
        """One seed's number; a censored one as "> budget"."""
        value, censored = score
        return f"> {fmt(value)}" if censored else fmt(value)

    def progress(self, run_dir: Path, step: int) -> float | None:
        """One seed's intermediate number at env step `step`, or None when it is not known yet
        (the seed has not got that far, or has not evaluated yet)."""
        done = is_complete(run_dir)
        if not done and last_timesteps(run_dir) < step:
            return None
        base = _base(self.key)
        if base == "steps_to_success":
            return float(min(step, self.value(read_json(Path(run_dir) / SUMMARY)))) if done else float(step)
        column = EVAL_COLUMN.get(base)
        if column is None:
            return None
        if done:
            last_step = last_timesteps(run_dir)
            if step >= last_step:
                return self.value(read_json(Path(run_dir) / SUMMARY))
        try:
            rows = read_metrics(run_dir)
        except MotorlabError:
            return None
        seen = [r[column] for r in rows if r.get("timesteps", math.inf) <= step and not math.isnan(r.get(column, math.nan))]
        return seen[-1] if seen else None


def budget_of(run_dir: Path) -> int | None:
    """The env-step budget a run was started with, as its kind reads it from the folder's config.toml
    (written when it starts); None for a kind without one, or a folder not yet claimed."""
    from motorlab.claims import read_claim
    from motorlab.kinds import KINDS  # here, not above: a Ray worker imports this module for every trial

    claim = read_claim(run_dir)
    kind = KINDS.get(claim.kind) if claim is not None else None
    if kind is None:
        return None
    try:
        return kind.planned_steps_of(read_config(run_dir))
    except (MotorlabError, OSError):
        return None


def steps_run(run_dir: Path) -> int:
    """Env steps a run has trained so far (all of them once it finished)."""
    return last_timesteps(run_dir)


MAX_FILL_REPORTS = 200  # numbers a finished trial reports for the steps after its end (one DB write each)


def iqm(values: list[float]) -> float:
    """rliable's interquartile mean, scipy.stats.trim_mean(values, 0.25), without importing scipy
    (a Ray worker imports this module for every trial); below 4 values it cuts nothing: the mean."""
    a = np.sort(np.asarray(values, dtype=float))
    cut = int(0.25 * a.size)
    return float(a[cut:a.size - cut].mean())


def trial_horizon(dirs: list[Path]) -> int:
    """The env steps a trial's seeds were to train (their budget; what they ran when it is unknown)."""
    return max(budget_of(d) or steps_run(d) for d in dirs)


class Reporter:
    """A trial's intermediate numbers (`Objective.combine` over its seeds) at each multiple of `every` env steps
    that every seed has reached, read from their run folders. Both backends report them: the local
    one to its Optuna trial (for the pruner), the ray one to Ray Tune (for its scheduler, ASHA)."""

    def __init__(self, objective: Objective, every: int, dirs: list[Path]):
        self.objective = objective
        self.every = every
        self.dirs = dirs
        self.last_step = 0

    def _at(self, step: int) -> float | None:
        values = [self.objective.progress(d, step) for d in self.dirs]
        if any(v is None for v in values):
            return None
        return self.objective.combine(values)

    def reached(self) -> list[tuple[int, float]]:
        """(step, number) for every step reached since the last call, in order."""
        if not self.objective.prunable:
            return []
        numbers = []
        reached = max(steps_run(d) for d in self.dirs)  # a finished seed knows every later step: stop at the front
        while self.last_step + self.every <= reached and (value := self._at(self.last_step + self.every)) is not None:
            self.last_step += self.every
            numbers.append((self.last_step, value))
        return numbers

    def filled(self, horizon: int) -> list[tuple[int, float]]:
        """A finished trial's numbers for the remaining steps up to `horizon` (its budget), so that
        trials still running are compared against it there (each is final: the runs have ended)."""
        if not self.objective.prunable or not all(is_complete(d) for d in self.dirs):
            return []
        numbers = []
        for _ in range(MAX_FILL_REPORTS):
            step = self.last_step + self.every
            if step > horizon:
                break
            value = self._at(step)
            if value is None:
                break
            numbers.append((step, value))
            self.last_step = step
        return numbers
