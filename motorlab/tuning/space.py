"""`--space KEY=DIST ...`: what a tuning search may vary, and how Optuna samples it.

A KEY names what the trial's command line or recipe changes, exactly as `sweep --grid` does
(an option such as lr or n_envs, a recipe FIELD or STEP.FIELD); for a command line, `set.KEY`
(or a KEY that is not an option of the command) is an SB3 hyperparameter, passed as
`--set KEY=VALUE`. A DIST is one of

    loguniform:LOW,HIGH   floats, sampled on a log scale (learning rates)
    uniform:LOW,HIGH      floats
    int:LOW,HIGH          integers, both ends included
    choice:A,B,C          one of the listed values, as written (choice:64|128 also splits on |)

From Python (`motorlab.tune(..., space={...})`) a key's DIST is that text, or Optuna's own distribution
object (`FloatDistribution(1e-5, 1e-2, log=True)`, `IntDistribution(1, 4)`,
`CategoricalDistribution([64, 128])`). Sampled numbers go to the trial as the command line would give
them (text, read by the target's settings as typed text is); choices as they were given (text from the
command line, Python's own values from Python).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Literal

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
    choices: tuple[Any, ...] = ()  # text from the command line; Python's values (str, int, float, bool) from Python

    @property
    def is_hyperparam(self) -> bool:
        """Given explicitly as `set.KEY`: an SB3 hyperparameter (`--set KEY=VALUE`)."""
        return self.key.startswith(HYPERPARAM_PREFIX)

    @property
    def name(self) -> str:
        """The key without its `set.` prefix: the option, field or hyperparameter name."""
        return self.key.removeprefix(HYPERPARAM_PREFIX)

    def suggest(self, trial: optuna.Trial) -> Any:
        """Sample (or, for an enqueued or retried trial, read back) this key's value, as the trial gets it."""
        if self.kind == "choice":
            return self.value(trial.suggest_categorical(self.key, list(self.choices)))
        if self.kind == "int":
            return self.value(trial.suggest_int(self.key, int(self.low), int(self.high)))
        return self.value(trial.suggest_float(self.key, self.low, self.high, log=self.kind == "loguniform"))

    def distribution(self) -> optuna.distributions.BaseDistribution:
        """The same distribution as Optuna's object (what `suggest` samples from), for samplers that
        take the space up front (Ray Tune's OptunaSearch)."""
        if self.kind == "choice":
            return optuna.distributions.CategoricalDistribution(list(self.choices))
        if self.kind == "int":
            return optuna.distributions.IntDistribution(int(self.low), int(self.high))
        return optuna.distributions.FloatDistribution(self.low, self.high, log=self.kind == "loguniform")

    def value(self, value: object) -> Any:
        """A sampled value as the trial gets it: a choice as it was given, a number as its text."""
        if self.kind == "choice":
            return value
        if self.kind == "int":
            return str(int(value))  # type: ignore[call-overload]
        return repr(float(value))  # type: ignore[arg-type]

    def item(self) -> str:
        """KEY=KIND:ARGS as `--space` gives it, bounds written exactly, so that `parse_dist` reads back
        this distribution (choices from Python: their text, as the command line gives them)."""
        if self.kind == "choice":
            texts = [c if isinstance(c, str) else json.dumps(c) for c in self.choices]
            return f"{self.key}=choice:{('|' if any(',' in t for t in texts) else ',').join(texts)}"  # parse_dist's split
        low, high = (str(int(self.low)), str(int(self.high))) if self.kind == "int" else (repr(self.low), repr(self.high))
        return f"{self.key}={self.kind}:{low},{high}"

    def describe(self) -> str:
        if self.kind == "choice":
            return f"{self.kind}:{','.join(c if isinstance(c, str) else json.dumps(c) for c in self.choices)}"
        return f"{self.kind}:{self.low:g},{self.high:g}"


@dataclass(frozen=True)
class Space:
    """A search space as `motorlab tune`'s settings hold it, read (`parse_space`): each key's distribution,
    in the order given. A box, not a dict, because settings check every table they hold for values
    config.toml can record, and a distribution is none (the search records `describe()`'s text)."""

    dists: dict[str, Dist]


def parse_space(items: list[str] | dict[str, Any] | None) -> dict[str, Dist]:
    """{key: Dist} from `KEY=KIND:ARGS` items (the command line's) or from {KEY: KIND:ARGS or an Optuna
    distribution} (Python's), in the order given.

    Raises:
        MotorlabError: no items, an item without "=" or ":", an unknown kind, bounds that are not
            numbers or not ordered, a non-positive loguniform bound, fewer than two choices, a key
            given twice, an Optuna distribution with a step.
    """
    if not items:
        raise MotorlabError(f"give at least one --space KEY=DIST to search, e.g. {EXAMPLE}.")
    if isinstance(items, dict):
        return {key.strip(): from_python(key.strip(), value) for key, value in items.items()}
    space: dict[str, Dist] = {}
    for item in items:
        dist = parse_dist(item)
        if dist.key in space:
            raise MotorlabError(f"--space {dist.key} is given twice; give it once.")
        space[dist.key] = dist
    return space


def from_python(key: str, value: Any) -> Dist:
    """One key of a space given in Python: KIND:ARGS text, or an Optuna distribution.

    Raises:
        MotorlabError: what `dist` refuses, a stepped or other distribution, a value of another type.
    """
    dists = optuna.distributions
    if isinstance(value, str):
        return dist(key, value, f"{key}={value}")
    if isinstance(value, dists.CategoricalDistribution):
        choices = tuple(value.choices)
        if len(choices) < 2 or len(set(map(repr, choices))) != len(choices):
            raise MotorlabError(f"space {key!r}: give at least two distinct choices.")
        return Dist(key, "choice", choices=choices)
    if isinstance(value, (dists.FloatDistribution, dists.IntDistribution)):
        if value.step not in (None, 1) or (isinstance(value, dists.FloatDistribution) and value.step is not None):
            raise MotorlabError(f"space {key!r}: a stepped distribution is not searched; give it without step.")
        kind: Kind = "int" if isinstance(value, dists.IntDistribution) else "loguniform" if value.log else "uniform"
        if kind == "int" and value.log:
            raise MotorlabError(f"space {key!r}: a log-scaled integer is not searched; give IntDistribution(low, high).")
        return dist(key, f"{kind}:{value.low},{value.high}", f"{key}={value!r}")
    raise MotorlabError(f"space {key!r}: give KIND:ARGS text (e.g. 'loguniform:1e-5,1e-2') or an Optuna "
                        f"distribution (FloatDistribution, IntDistribution, CategoricalDistribution), not "
                        f"{type(value).__name__}.")


def parse_dist(item: str) -> Dist:
    """One `KEY=KIND:ARGS` item (see parse_space)."""
    key, sep, rest = item.partition("=")
    if not sep or not key.strip():
        raise MotorlabError(f"--space {item!r}: write KEY=KIND:ARGS, e.g. {EXAMPLE}.")
    return dist(key.strip(), rest, item)


def dist(key: str, rest: str, item: str) -> Dist:
    """The distribution KIND:ARGS (`rest`) of `key`; errors quote `item`, as it was given."""
    kind, colon, args = rest.partition(":")
    kind = kind.strip().lower()
    if not key or not colon:
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
