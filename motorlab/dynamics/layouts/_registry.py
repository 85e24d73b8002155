"""The layout registry (motorlab.dynamics.layouts re-exports it): the layouts by name, and an env's
layout built by name."""

from __future__ import annotations

import functools
import importlib
import sys
from dataclasses import replace
from typing import TYPE_CHECKING, Sequence

from motorlab.errors import MotorlabError, did_you_mean
from motorlab.plugins import help_lines, module_names

if TYPE_CHECKING:  # numpy and gymnasium come with the layouts, not with --help
    import gymnasium as gym

    from motorlab.dynamics.layouts.base import LayoutSpec
    from motorlab.dynamics.state import KeySlice, Reached, StateLayout

LAYOUTS = __package__  # motorlab.dynamics.layouts: its __path__ is read at each look-up
DEFAULT = "observation"


@functools.cache
def names() -> tuple[str, ...]:
    """Every layout's name (its module's): the default first."""
    return module_names(sys.modules[LAYOUTS].__path__, first=DEFAULT)


def check_name(name: str, auto: bool = True) -> str:
    """`name` if it is a layout (or "auto"), else one line naming the choices."""
    choices = ("auto", *names()) if auto else names()
    if name not in choices:
        raise MotorlabError(f"unknown state layout {name!r}; choose {', '.join(choices)}{did_you_mean(name, choices)}.")
    return name


def spec(name: str) -> LayoutSpec:
    check_name(name, auto=False)
    spec = getattr(importlib.import_module(f"{LAYOUTS}.{name}"), "LAYOUT", None)
    if spec is None:
        raise TypeError(f"{LAYOUTS}.{name} defines no LAYOUT (a LayoutSpec); every module in {LAYOUTS} but base "
                        "is one layout.")
    return spec


def about() -> str:
    """Each layout in a line, for --help: its module docstring's first line, read without importing it."""
    return help_lines(LAYOUTS, names(), "--state")


def layout_for(env_id: str, obs_dim: int, name: str = "auto", keys: Sequence[KeySlice] = ()) -> StateLayout:
    """The state layout NAME ("auto": the env's catalogue entry's `state_layout`, reacher for Reacher
    ids, else the observation; always the observation for a Dict one), for an env with `obs_dim`
    observations (`keys`: their Dict keys' slices, see `motorlab.dynamics.state.observation_keys`)."""
    if name == "auto":
        from motorlab.envs.catalog import facts

        name = facts(env_id).state_layout if not keys else DEFAULT
    return spec(name).build(env_id, obs_dim, tuple(keys))


def env_layout(env: gym.Env, env_id: str, name: str = "auto") -> StateLayout:
    """`layout_for` the env `make_env` built (its flattened observation, and its Dict keys if any).

    With an observation history (--history K) the state is the K stacked observations ("auto": the
    observation layout; a layout that reads one observation, reacher, or the goal keys of a Dict
    observation, is refused in one line)."""
    import numpy as np

    from motorlab.dynamics.state import observation_keys, stacked_frames

    frames = stacked_frames(env)
    obs_dim = int(np.prod(env.observation_space.shape))
    if frames == 1:
        return layout_for(env_id, obs_dim, name, observation_keys(env))
    if name != "auto" and spec(name).one_observation:
        raise MotorlabError(f"the {name} state layout reads one observation, and with --history {frames} the state "
                            f"is {frames} stacked observations; use --state observation (or auto).")
    if observation_keys(env):
        raise MotorlabError(f"{env_id}'s Dict observation names its goal keys in one observation, and --history "
                            f"{frames} stacks {frames} of them; plan on it without --history.")
    return replace(layout_for(env_id, obs_dim, DEFAULT if name == "auto" else name), frames=frames)


def reaching(key: str) -> Reached | None:
    """The reaching point whose summary keys start with `key` (a layout's own, or "achieved_goal")."""
    from motorlab.dynamics.state import ACHIEVED, Reached

    if key == ACHIEVED:
        return Reached((), ACHIEVED, "achieved goal")
    return next((r for n in names() if (r := spec(n).reaching) is not None and r.key == key), None)


def reached_of(name: str, labels: Sequence[str], goal_labels: Sequence[str]) -> Reached | None:
    """What a recorded layout (a model's or transitions' `state_layout`, `state_labels`, `goal_labels`)
    reaches for its goal with: the layout's own, else the achieved_goal entries where the goal is the
    desired_goal of the same size, else None."""
    from motorlab.dynamics.state import reached_by

    return reached_by(spec(name).reaching if name in names() else None, labels, goal_labels)
