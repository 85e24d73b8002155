"""`--grid key=v1,v2 ...`: the settings a sweep tries, as the Cartesian product of every key's values."""

from __future__ import annotations

import itertools
import re

from motorlab.errors import MotorlabError

EXAMPLE = "--grid lr=3e-4,1e-3 (values with commas: separate them with |, e.g. --grid lr='linear:1e-3,0|3e-4')"


def parse_grid(items: list[str] | None) -> dict[str, list[str]]:
    """{key: [values]} from `key=v1,v2` items, in the order given.

    Values are split on "|" when there is one (schedules such as linear:1e-3,0 contain
    commas), else on ",".

    Raises:
        MotorlabError: an item without "=", an empty key or value, a key given twice.
    """
    grid: dict[str, list[str]] = {}
    for item in items or []:
        key, sep, rest = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise MotorlabError(f"--grid {item!r}: write KEY=VALUE1,VALUE2, e.g. {EXAMPLE}.")
        values = [v.strip() for v in rest.split("|" if "|" in rest else ",")]
        if not rest.strip() or any(v == "" for v in values):
            raise MotorlabError(f"--grid {item!r}: empty value; write KEY=VALUE1,VALUE2, e.g. {EXAMPLE}.")
        if key in grid:
            raise MotorlabError(f"--grid {key} is given twice; give all its values in one --grid {key}=... .")
        if len(set(values)) != len(values):
            raise MotorlabError(f"--grid {item!r}: a value is repeated; each setting runs once per seed.")
        grid[key] = values
    return grid


def settings(grid: dict[str, list[str]]) -> list[dict[str, str]]:
    """Every combination of the grid's values ([{}] for an empty grid: the target as given)."""
    keys = list(grid)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(grid[k] for k in keys))]


def label(setting: dict[str, str]) -> str:
    """A setting's name, also its folder name: "lr=0.001,n_envs=2" ("default" with no grid)."""
    if not setting:
        return "default"
    text = ",".join(f"{k.lstrip('-')}={v}" for k, v in setting.items())
    return re.sub(r"[^A-Za-z0-9=.,:+_-]", "_", text)  # no "/" or spaces in folder names
