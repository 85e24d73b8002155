"""The planner registry (motorlab.planning.planners re-exports it): the planners by name, their
settings and their lines in --help."""

from __future__ import annotations

import functools
import importlib
import sys
from typing import Any

from motorlab.errors import MotorlabError, did_you_mean
from motorlab.plugins import help_lines, module_names

PLANNERS = __package__  # motorlab.planning.planners: its __path__ is read at each look-up


@functools.cache
def names() -> tuple[str, ...]:
    """Every planner's name (its module's), in a fixed order: cem first, the default."""
    return module_names(sys.modules[PLANNERS].__path__, first="cem")


def _module(name: str) -> Any:
    if name not in names():
        raise MotorlabError(f"--optimizer {name!r}: choose {', '.join(names())}{did_you_mean(name, names())}.")
    return importlib.import_module(f"{PLANNERS}.{name}")


def planner_class(name: str) -> type:
    return _module(name).PLANNER


def about() -> str:
    """Each planner in a line, for --help: its module docstring's first line, read without importing the
    module (a planner imports torch; --help does not need it)."""
    return help_lines(PLANNERS, names(), "--optimizer")


def settings_of(name: str) -> tuple[str, ...]:
    """The plan settings (horizon, population, ...) the planner `name` takes."""
    return _module(name).SETTINGS


def make_planner(optimizer: str, score: Any, low: Any, high: Any, **settings: Any) -> Any:
    return planner_class(optimizer)(score, low, high, **settings)
