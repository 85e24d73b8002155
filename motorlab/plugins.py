"""Registries of one module per entry (planners, state layouts): the entries' names, and their lines in
--help read from the modules' docstrings without importing them (an entry may import torch; --help does
not need it). Each registry keeps its own look-up and errors; this is what they share.

Hand-written rather than entry points: the entries live inside motorlab's own packages and are found by
`pkgutil`, as `algos` finds algorithms, so adding one is adding a file with no packaging metadata."""

from __future__ import annotations

import ast
import importlib.util
import pkgutil
from pathlib import Path
from typing import Iterable


def module_names(path: Iterable[str], first: str, skip: Iterable[str] = ("base",)) -> tuple[str, ...]:
    """The modules in a package's `path` (its `__path__`), `first` (the default) first, then by name;
    private modules (`_name`) and those in `skip` are not entries."""
    skipped = set(skip)
    found = sorted(m.name for m in pkgutil.iter_modules(list(path)) if m.name not in skipped and not m.name.startswith("_"))
    return tuple(sorted(found, key=lambda n: (n != first, n)))


def help_lines(package: str, names: Iterable[str], flag: str) -> str:
    """Each entry in a line, "; "-joined: its module docstring's first line, with its leading "`FLAG NAME`: "
    written "NAME: " (the entry's name alone where it has no docstring)."""
    lines = []
    for name in names:
        found = importlib.util.find_spec(f"{package}.{name}")  # finds its file; runs nothing of it
        doc = ast.get_docstring(ast.parse(Path(found.origin).read_text())) if found and found.origin else None
        lines.append((doc or name).splitlines()[0].replace(f"`{flag} {name}`: ", f"{name}: ").rstrip("."))
    return "; ".join(lines)
