"""`--grid key=v1,v2 ...`: the settings a sweep tries, as the Cartesian product of every key's values."""

from __future__ import annotations

import hashlib
import itertools
import json
import re
from typing import Any

from motorlab.errors import MotorlabError, mask_secrets

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


def check_grid(grid: dict[str, Any]) -> dict[str, list[Any]]:
    """A grid given in Python, {key: [values]}: the values as they are (numbers stay numbers; text is read
    as the command line reads it), each key's list non-empty and without repeats.

    Raises:
        MotorlabError: a key that is not a non-empty string, a value list that is empty, not a list, or
            repeats a value.
    """
    out: dict[str, list[Any]] = {}
    for key, values in grid.items():
        if not isinstance(key, str) or not key.strip() or "=" in key:
            raise MotorlabError(f"grid key {key!r}: give a setting's name, e.g. grid={{'lr': [3e-4, 1e-3]}}.")
        if isinstance(values, (str, bytes)) or not isinstance(values, (list, tuple)) or not values:
            raise MotorlabError(f"grid {key!r}: give a non-empty list of values, e.g. grid={{{key!r}: [...]}}.")
        texts = [json.dumps(v, sort_keys=True, default=str) for v in values]
        if len(set(texts)) != len(texts):
            raise MotorlabError(f"grid {key!r}: a value is repeated; each setting runs once per seed.")
        out[key.strip()] = list(values)
    return out


def read_grid(grid: list[str] | dict[str, Any] | None) -> dict[str, list[Any]]:
    """A grid as the command line gives it (`parse_grid`) or as Python does (`check_grid`)."""
    return check_grid(grid) if isinstance(grid, dict) else parse_grid(grid)


def settings(grid: dict[str, list[Any]]) -> list[dict[str, Any]]:
    """Every combination of the grid's values ([{}] for an empty grid: the target as given)."""
    keys = list(grid)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(grid[k] for k in keys))]


SLUG_CHARS = 60  # of a folder name's readable part: a long value is cut there (its hash keeps it apart)
HASH_CHARS = (8, 16, 64)  # of its hash: longer only where two settings of one sweep share the shorter


def label(setting: dict[str, Any], digits: int = HASH_CHARS[0]) -> str:
    """A setting's name, also its folder name: a readable slug of its values and a hash of them as given,
    "lr=0.001,n_envs=2-85f7d7a1" ("default" with no grid). Slugs alone collide ("a b" and "a_b",
    unicode, long values cut short), and two settings in one folder would mix their runs; the hash of the
    exact text keeps every setting apart, and gives the same name for the same values (--resume finds
    its trials by it). Credentials in a value are masked in the slug, never written into a path."""
    if not setting:
        return "default"
    text = ",".join(f"{k.lstrip('-')}={v}" for k, v in setting.items())
    slug = re.sub(r"[^A-Za-z0-9=.,:+_-]", "_", mask_secrets(text))[:SLUG_CHARS]  # no "/" or spaces in folder names
    digest = hashlib.sha256(json.dumps(list(setting.items()), default=str).encode()).hexdigest()[:digits]
    return f"{slug}-{digest}"


def labels(settings: list[dict[str, Any]]) -> list[str]:
    """Each setting's name (`label`), distinct for distinct settings: the hash is lengthened in the rare
    sweep where two settings share its first digits (the whole SHA-256 at most).

    Raises:
        MotorlabError: a setting given twice (one folder would hold both).
    """
    for digits in HASH_CHARS:
        names = [label(s, digits) for s in settings]
        if len(set(names)) == len(names):
            return names
    raise MotorlabError("a setting of the grid is given twice; give each combination of values once.")
