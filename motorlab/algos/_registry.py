"""The algorithm registry (motorlab.algos re-exports it): every module of the package that defines
`ALGORITHM`, found by `pkgutil` at the first look-up, and the look-ups --algo, --preset and --help use."""

from __future__ import annotations

import importlib
import sys
from functools import cache
from typing import Any

from motorlab.algos.base import Algorithm, SB3Algorithm
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.plugins import module_names

PACKAGE = __package__  # motorlab.algos: its __path__ is read at each look-up, so an extended one counts
NOT_ALGORITHMS = {"base"}


@cache
def registry() -> dict[str, Algorithm]:
    """Every algorithm, by name, from the modules of this package (in module order)."""
    found: dict[str, Algorithm] = {}
    for name in module_names(sys.modules[PACKAGE].__path__, first="", skip=NOT_ALGORITHMS):  # by name
        module = importlib.import_module(f"{PACKAGE}.{name}")
        algo = getattr(module, "ALGORITHM", None)
        if not isinstance(algo, Algorithm):
            raise TypeError(f"{module.__name__} defines no ALGORITHM (an Algorithm); every module in "
                            f"{PACKAGE} but {', '.join(sorted(NOT_ALGORITHMS))} is one algorithm.")
        if algo.name in found:
            raise TypeError(f"{module.__name__} and another module both define the algorithm {algo.name!r}.")
        found[algo.name] = algo
    return found


def names() -> list[str]:
    """The algorithm names, as --algo takes them."""
    return list(registry())


def get(name: str) -> Algorithm:
    """The algorithm called `name`.

    Raises:
        MotorlabError: an unknown name, with close matches and the known ones.
    """
    algos = registry()
    if name not in algos:
        raise MotorlabError(f"--algo {name!r}: unknown algorithm{did_you_mean(name, algos)}; algorithms: "
                            f"{', '.join(algos)}.")
    return algos[name]


def of_network(network: Any) -> SB3Algorithm | None:
    """The SB3 algorithm whose policy network class `network` is an instance of (exactly)."""
    for algo in registry().values():
        if isinstance(algo, SB3Algorithm) and any(type(network) is cls for cls in algo.network_classes().values()):
            return algo
    return None


@cache
def presets() -> dict[str, dict[str, Any]]:
    """Every algorithm's presets as TrainConfig fields (the algorithm's name included), by name."""
    out: dict[str, dict[str, Any]] = {}
    for algo in registry().values():
        for name, preset in algo.presets.items():
            if name in out:
                raise TypeError(f"two algorithms define the preset {name!r}.")
            out[name] = {"algo": algo.name, **preset.settings}
    return out


def preset_help() -> str:
    """Each preset with its one-line description, for --help."""
    return "; ".join(f"{name}: {preset.about}" for algo in registry().values()
                     for name, preset in algo.presets.items())


def summary_help() -> str:
    """Each algorithm with its one-line summary, for --help."""
    return "; ".join(f"{a.name}: {a.summary}" for a in registry().values())


def titles_with(flag: str) -> str:
    """The algorithms with a true `flag` (her, clip_range), as messages name them: "SAC, TD3"."""
    return ", ".join(a.title for a in registry().values() if getattr(a, flag))


def eval_cadence_help() -> str:
    """What eval_every defaults to, algorithm by algorithm, for --help."""
    by_cadence: dict[str, list[str]] = {}
    for a in registry().values():
        by_cadence.setdefault(a.eval_cadence, []).append(a.title)
    return "; ".join(f"{cadence} for {', '.join(titles)}" for cadence, titles in by_cadence.items() if cadence)
