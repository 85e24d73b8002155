"""What a forward model sees of an env: a state extracted from the observation.

A `StateLayout` names the state's entries and, where the task has one, a goal the
planner's cost needs but the dynamics do not predict (Reacher's target). The default
layout is the observation itself; `reacher` is the reference notebook's 8-number state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from motorlab.errors import MotorlabError


@dataclass(frozen=True)
class StateLayout:
    name: str
    labels: tuple[str, ...]
    goal_labels: tuple[str, ...] = ()
    _state: Callable[[np.ndarray], np.ndarray] | None = field(default=None, repr=False, compare=False)
    _goal: Callable[[np.ndarray], np.ndarray] | None = field(default=None, repr=False, compare=False)

    @property
    def size(self) -> int:
        return len(self.labels)

    def state(self, obs: np.ndarray) -> np.ndarray:
        """(..., obs_dim) observations -> (..., size) states."""
        return obs if self._state is None else self._state(obs)

    def goal(self, obs: np.ndarray) -> np.ndarray:
        """(..., obs_dim) observations -> (..., n_goal) goals (empty for goal-free layouts)."""
        if self._goal is None:
            return np.zeros(obs.shape[:-1] + (0,), dtype=obs.dtype)
        return self._goal(obs)


REACHER_LABELS = ("cos q1", "cos q2", "sin q1", "sin q2", "dq1", "dq2", "tip x", "tip y")


def _reacher_state(obs: np.ndarray) -> np.ndarray:
    # obs: cos(2), sin(2), target xy (2), qvel (2), fingertip - target (2 in v5, 3 in v4)
    tip = obs[..., 8:10] + obs[..., 4:6]
    return np.concatenate([obs[..., 0:4], obs[..., 6:8], tip], axis=-1)


REACHER = StateLayout("reacher", REACHER_LABELS, ("target x", "target y"),
                      _reacher_state, lambda obs: obs[..., 4:6])


def xy_columns(labels) -> list[int] | None:
    """Columns of the fingertip x-y ("tip x", "tip y") in a state with these labels, or None."""
    labels = list(labels)
    return [labels.index("tip x"), labels.index("tip y")] if {"tip x", "tip y"} <= set(labels) else None


def layout_for(env_id: str, obs_dim: int, name: str = "auto") -> StateLayout:
    """The state layout NAME ("auto": reacher for Reacher ids, else the observation)."""
    if name == "auto":
        name = "reacher" if env_id.startswith("Reacher-") else "observation"
    if name == "reacher":
        if obs_dim not in (10, 11):
            raise MotorlabError(f"the reacher state layout needs Reacher's 10 (v5) or 11 (v4) observations, "
                                f"not {obs_dim}; use --state observation for {env_id}.")
        return REACHER
    if name == "observation":
        return StateLayout("observation", tuple(f"obs[{i}]" for i in range(obs_dim)))
    raise MotorlabError(f"unknown state layout {name!r}; choose auto, reacher or observation.")
