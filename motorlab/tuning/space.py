"""`--space KEY=DIST ...`: what a tuning search may vary, and how Optuna samples it.

A KEY names what the trial's command line or recipe changes, exactly as `sweep --grid` does
(an option such as lr or n_envs, a recipe FIELD or STEP.FIELD); for a command line, `set.KEY`
(or a KEY that is not an option of the command) is an SB3 hyperparameter, passed as
`--set KEY=VALUE`. A DIST is one of

    loguniform:LOW,HIGH   floats, sampled on a log scale (learning rates)
    uniform:LOW,HIGH      floats
    int:LOW,HIGH          integers, both ends included
    choice:A,B,C          one of the listed values, as written (choice:64|128 also splits on |)

Sampled values become text, because a trial is a command line.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import optuna

from motorlab.errors import MotorlabError, did_you_mean

Kind = Literal["loguniform", "uniform", "int", "choice"]
KINDS: tuple[Kind, ...] = ("loguniform", "uniform", "int", "choice")
EXAMPLE = "--space lr=loguniform:1e-5,1e-2 --space n_envs=choice:1,2"
HYPERPARAM_PREFIX = "set."


@dataclass(frozen=True)
class Dist:
    """One searched key: its distribution, bounds (numeric kinds) or choices."""

    key: str
    kind: Kind
    low: float = 0.0
    high: float = 0.0
    choices: tuple[str, ...] = ()

    @property
    def is_hyperparam(self) -> bool:
        """Given explicitly as `set.KEY`: an SB3 hyperparameter (`--set KEY=VALUE`)."""
        return self.key.startswith(HYPERPARAM_PREFIX)

    @property
    def name(self) -> str:
        """The key without its `set.` prefix: the option, field or hyperparameter name."""
        return self.key.removeprefix(HYPERPARAM_PREFIX)

    def suggest(self, trial: optuna.Trial) -> str:
        """Sample (or, for an enqueued or retried trial, read back) this key's value, as text."""
        if self.kind == "choice":
            return self.text(trial.suggest_categorical(self.key, list(self.choices)))
        if self.kind == "int":
            return self.text(trial.suggest_int(self.key, int(self.low), int(self.high)))
        return self.text(trial.suggest_float(self.key, self.low, self.high, log=self.kind == "loguniform"))

    def distribution(self) -> optuna.distributions.BaseDistribution:
        """The same distribution as Optuna's object (what `suggest` samples from), for samplers that
        take the space up front (Ray Tune's OptunaSearch)."""
        if self.kind == "choice":
            return optuna.distributions.CategoricalDistribution(list(self.choices))
        if self.kind == "int":
            return optuna.distributions.IntDistribution(int(self.low), int(self.high))
        return optuna.distributions.FloatDistribution(self.low, self.high, log=self.kind == "loguniform")

    def text(self, value: object) -> str:
        """A sampled value as the trial's command line (or recipe) gets it."""
        if self.kind == "choice":
            return str(value)
        if self.kind == "int":
            return str(int(value))  # type: ignore[call-overload]
        return repr(float(value))  # type: ignore[arg-type]

    def describe(self) -> str:
        return f"{self.kind}:{','.join(self.choices)}" if self.kind == "choice" else f"{self.kind}:{self.low:g},{self.high:g}"


def parse_space(items: list[str] | None) -> dict[str, Dist]:
    """{key: Dist} from `KEY=KIND:ARGS` items, in the order given.

    Raises:
        MotorlabError: no items, an item without "=" or ":", an unknown kind, bounds that are not
            numbers or not ordered, a non-positive loguniform bound, fewer than two choices, a key
            given twice.
    """
    if not items:
        raise MotorlabError(f"give at least one --space KEY=DIST to search, e.g. {EXAMPLE}.")
    space: dict[str, Dist] = {}
    for item in items:
        dist = parse_dist(item)
        if dist.key in space:
            raise MotorlabError(f"--space {dist.key} is given twice; give it once.")
        space[dist.key] = dist
    return space


def parse_dist(item: str) -> Dist:
    """One `KEY=KIND:ARGS` item (see parse_space)."""
    key, sep, rest = item.partition("=")
    key = key.strip()
    kind, colon, args = rest.partition(":")
    kind = kind.strip().lower()
    if not sep or not key or not colon:
        raise MotorlabError(f"--space {item!r}: write KEY=KIND:ARGS, e.g. {EXAMPLE}.")
    if kind not in KINDS:
        raise MotorlabError(f"--space {item!r}: unknown distribution {kind!r}{did_you_mean(kind, KINDS)}; "
                            f"use loguniform:LOW,HIGH, uniform:LOW,HIGH, int:LOW,HIGH or choice:A,B,C.")
    values = [v.strip() for v in args.split("|" if "|" in args else ",")]
    if kind == "choice":
        if len(values) < 2 or any(v == "" for v in values):
            raise MotorlabError(f"--space {item!r}: give at least two non-empty choices, e.g. {key}=choice:64,128.")
        if len(set(values)) != len(values):
            raise MotorlabError(f"--space {item!r}: a choice is repeated.")
        return Dist(key, "choice", choices=tuple(values))
    if len(values) != 2:
        raise MotorlabError(f"--space {item!r}: {kind} takes two bounds, LOW,HIGH, e.g. {key}={kind}:"
                            f"{'1e-5,1e-2' if kind == 'loguniform' else '1,10'}.")
    try:
        low, high = (int(v) for v in values) if kind == "int" else (float(v) for v in values)
    except ValueError:
        raise MotorlabError(f"--space {item!r}: the bounds {args!r} are not "
                            f"{'integers' if kind == 'int' else 'numbers'}.") from None
    if not low < high:
        raise MotorlabError(f"--space {item!r}: LOW must be below HIGH.")
    if kind == "loguniform" and low <= 0:
        raise MotorlabError(f"--space {item!r}: loguniform bounds must be positive.")
    return Dist(key, kind, float(low), float(high))
