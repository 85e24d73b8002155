"""Studies: run a recipe's steps in order, then tabulate and plot them.

The runner is imported when it is first used: `motorlab.studies.run_command` (the `run` command, read
whenever the CLI starts) must not bring matplotlib and the report with it."""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["Execution", "run_study"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(importlib.import_module("motorlab.studies.runner"), name)
    raise AttributeError(f"module 'motorlab.studies' has no attribute {name!r}")
