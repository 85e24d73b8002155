"""What a forward model sees of an env: a state extracted from the observation.

A `StateLayout` names the state's entries and, where the task has one, a goal the
planner's cost needs but the dynamics do not predict (Reacher's target). The default
layout is the observation itself; `reacher` is the reference notebook's 8-number state.

An env with a Dict observation (a goal-conditioned task: observation, achieved_goal,
desired_goal) is seen flattened, as `gymnasium.spaces.flatten` lays it out
(motorlab.envs.spaces): the layout keeps each key's slice (`keys`), names the entries after
their keys ("achieved_goal[0]", ...), and takes the desired_goal as the planner's goal.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import gymnasium as gym
import numpy as np

from motorlab.envs.catalog import facts
from motorlab.envs.spaces import KeySlice, is_dict, obs_layout
from motorlab.errors import MotorlabError

ACHIEVED, DESIRED = "achieved_goal", "desired_goal"


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
        achieved, desired = self.key(ACHIEVED), self.key(DESIRED)
        if achieved is None or desired is None or achieved.stop - achieved.start != len(self.goal_labels):
            return None
        return slice(achieved.start, achieved.stop)

    def keys_json(self) -> list[dict] | None:
        """The keys' slices as transitions.npz and model.json record them (None for a Box observation)."""
        return [k.to_dict() for k in self.keys] or None


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


def _entry_labels(keys: Sequence[KeySlice]) -> tuple[str, ...]:
    return tuple(f"{k.key}[{i}]" for k in keys for i in range(k.stop - k.start))


def _observation_layout(obs_dim: int, keys: Sequence[KeySlice]) -> StateLayout:
    """The observation as the state; a Dict observation's entries named after their keys, and its
    desired_goal (if any) the planner's goal."""
    if not keys:
        return StateLayout("observation", tuple(f"obs[{i}]" for i in range(obs_dim)))
    if keys[-1].stop != obs_dim:
        raise MotorlabError(f"the observation has {obs_dim} entries and its Dict keys cover {keys[-1].stop}: a "
                            "wrapper changed the flat observation; collect and plan on the env without it.")
    desired = next((k for k in keys if k.key == DESIRED), None)
    if desired is None:
        return StateLayout("observation", _entry_labels(keys), keys=tuple(keys))
    cut = slice(desired.start, desired.stop)
    return StateLayout("observation", _entry_labels(keys), _entry_labels([desired]),
                       _goal=lambda obs: obs[..., cut], keys=tuple(keys))


def layout_for(env_id: str, obs_dim: int, name: str = "auto", keys: Sequence[KeySlice] = ()) -> StateLayout:
    """The state layout NAME ("auto": the env's catalogue entry's `state_layout`, reacher for Reacher
    ids, else the observation; always the observation for a Dict one), for an env with `obs_dim`
    observations (`keys`: their Dict keys' slices, see `observation_keys`)."""
    if name == "auto":
        name = facts(env_id).state_layout if not keys else "observation"
    if name == "reacher":
        if obs_dim not in (10, 11) or keys:
            raise MotorlabError(f"the reacher state layout needs Reacher's 10 (v5) or 11 (v4) observations, "
                                f"not {obs_dim}; use --state observation for {env_id}.")
        return REACHER
    if name == "observation":
        return _observation_layout(obs_dim, keys)
    raise MotorlabError(f"unknown state layout {name!r}; choose auto, reacher or observation.")


def stacked_frames(env: gym.Env) -> int:
    """How many observations `env`'s observation stacks (--history K: gymnasium's
    FrameStackObservation), 1 where it stacks none."""
    layer = env
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, gym.wrappers.FrameStackObservation):
            return int(layer.stack_size)
        layer = layer.env
    return 1


def env_layout(env: gym.Env, env_id: str, name: str = "auto") -> StateLayout:
    """`layout_for` the env `make_env` built (its flattened observation, and its Dict keys if any).

    With an observation history (--history K) the state is the K stacked observations ("auto": the
    observation layout; a layout that reads one observation, reacher, or the goal keys of a Dict
    observation, is refused in one line)."""
    frames = stacked_frames(env)
    obs_dim = int(np.prod(env.observation_space.shape))
    if frames == 1:
        return layout_for(env_id, obs_dim, name, observation_keys(env))
    if name == "reacher":
        raise MotorlabError(f"the reacher state layout reads one Reacher observation, and with --history {frames} "
                            f"the state is {frames} stacked observations; use --state observation (or auto).")
    if observation_keys(env):
        raise MotorlabError(f"{env_id}'s Dict observation names its goal keys in one observation, and --history "
                            f"{frames} stacks {frames} of them; plan on it without --history.")
    return replace(layout_for(env_id, obs_dim, "observation" if name == "auto" else name), frames=frames)
