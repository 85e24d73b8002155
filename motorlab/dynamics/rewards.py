"""Moved to `motorlab.dynamics.planner_rewards` (what the planner scores: builtin, user and learned
rewards and terminations), beside `motorlab.envs.rewards` (training's reward shaping), whose name it
shared. This module keeps code written before the move working, with a DeprecationWarning."""

from __future__ import annotations

import warnings
from typing import Any

import motorlab.dynamics.planner_rewards as _moved


def __getattr__(name: str) -> Any:
    value = getattr(_moved, name)  # an AttributeError names the module it was looked up in
    warnings.warn(f"motorlab.dynamics.rewards.{name} moved to motorlab.dynamics.planner_rewards.{name}",
                  DeprecationWarning, stacklevel=2)
    return value
