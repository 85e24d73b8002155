"""What a forward model sees of an env: a state extracted from the observation.

A `StateLayout` names the state's entries and, where the task has one, a goal the
planner's cost needs but the dynamics do not predict (Reacher's target), and what reaches for
that goal (`Reached`: Reacher's fingertip). The layouts themselves are one file each in
`motorlab.dynamics.layouts` (the default, `observation`, is the observation itself; `reacher`
the reference notebook's 8-number state); this module holds what they share.

An env with a Dict observation (a goal-conditioned task: observation, achieved_goal,
desired_goal) is seen flattened, as `gymnasium.spaces.flatten` lays it out
(motorlab.envs.spaces): the layout keeps each key's slice (`keys`), names the entries after
their keys ("achieved_goal[0]", ...), and takes the desired_goal as the planner's goal.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from motorlab.envs.spaces import KeySlice, is_dict, obs_layout

ACHIEVED, DESIRED = "achieved_goal", "desired_goal"


@dataclass(frozen=True)
class Reached:
    """What a layout reaches for its goal with: the state's columns the goal is compared with (Reacher's
    fingertip x-y), named for the numbers motorlab reports about it (`dynamics check`'s
    `<key>_error_mean_h<k>`, "<label> error")."""

    columns: tuple[int, ...]
    key: str  # the summary keys' prefix, e.g. "tip"
    label: str  # in words, e.g. "fingertip"
    unit: str = ""  # "m": shown in mm

    @property
    def scale(self) -> tuple[float, str]:
        """The factor and unit a figure of it is shown in (metres as mm)."""
        return (1000.0, "mm") if self.unit == "m" else (1.0, self.unit)

    def to_json(self) -> dict:
        return {"columns": list(self.columns), "key": self.key, "label": self.label, "unit": self.unit}


def achieved_columns(labels: Sequence[str], goal_labels: Sequence[str]) -> tuple[int, ...]:
    """The state's achieved_goal columns (labelled "achieved_goal[i]") where the goal is a desired_goal of
    the same size, else none: the one place a goal-conditioned task's reaching entries are read, for a
    live layout and for a recorded one (a model's `state_labels` and `goal_labels`) alike."""
    columns = tuple(i for i, label in enumerate(labels) if label.startswith(f"{ACHIEVED}["))
    return columns if columns and len(columns) == len(goal_labels) else ()


def reached_by(reaching: Reached | None, labels: Sequence[str], goal_labels: Sequence[str]) -> Reached | None:
    """What reaches for the goal: the layout's own (Reacher's fingertip), else a goal-conditioned task's
    achieved_goal (`achieved_columns`), else None."""
    if reaching is not None:
        return reaching
    columns = achieved_columns(labels, goal_labels)
    return Reached(columns, ACHIEVED, "achieved goal") if columns else None


@dataclass(frozen=True)
class StateLayout:
    name: str
    labels: tuple[str, ...]
    goal_labels: tuple[str, ...] = ()
    _state: Callable[[np.ndarray], np.ndarray] | None = field(default=None, repr=False, compare=False)
    _goal: Callable[[np.ndarray], np.ndarray] | None = field(default=None, repr=False, compare=False)
    # a Dict observation's keys and where each lies in the state (empty for a Box observation)
    keys: tuple[KeySlice, ...] = ()
    # observations stacked in the state (--history K: gymnasium's FrameStackObservation, flattened,
    # the newest last); what is written for one observation (a bundled reward) reads the newest
    frames: int = 1
    # what reaches for the goal, where the layout names it (else a Dict observation's achieved_goal)
    reaching: Reached | None = None

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

    def key(self, name: str) -> KeySlice | None:
        return next((k for k in self.keys if k.key == name), None)

    @property
    def achieved(self) -> slice | None:
        """The state's achieved_goal entries where the goal is the desired_goal of the same size
        (a goal-conditioned task): what the goal reward and the distance to the goal compare."""
        columns = achieved_columns(self.labels, self.goal_labels)
        return slice(columns[0], columns[-1] + 1) if columns else None

    @property
    def reached(self) -> Reached | None:
        """What reaches for the goal (`reached_by`)."""
        return reached_by(self.reaching, self.labels, self.goal_labels)

    def keys_json(self) -> list[dict] | None:
        """The keys' slices as transitions.npz and model.json record them (None for a Box observation)."""
        return [k.to_dict() for k in self.keys] or None


def observation_keys(env: gym.Env) -> tuple[KeySlice, ...]:
    """The slices of the keys of the Dict observation `env` flattens (make_env flattens one as
    `gymnasium.spaces.flatten` does), outermost Dict first; empty for a Box observation."""
    layer = env
    while True:
        if is_dict(layer.observation_space):
            return tuple(obs_layout(layer.observation_space))
        if not isinstance(layer, gym.Wrapper):
            return ()
        layer = layer.env


def stacked_frames(env: gym.Env) -> int:
    """How many observations `env`'s observation stacks (--history K: gymnasium's
    FrameStackObservation), 1 where it stacks none."""
    layer = env
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, gym.wrappers.FrameStackObservation):
            return int(layer.stack_size)
        layer = layer.env
    return 1
