"""What a state layout's module declares (`LAYOUT`): how it builds the layout for an env, and what it
reaches for its goal with when that is fixed (Reacher's fingertip)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from motorlab.dynamics.state import KeySlice, Reached, StateLayout


@dataclass(frozen=True)
class LayoutSpec:
    # (env_id, obs_dim, the Dict observation's key slices or ()) -> the layout; a MotorlabError where the
    # env's observation is not one it reads
    build: Callable[[str, int, tuple[KeySlice, ...]], StateLayout]
    # the layout's own reaching point, the same for every env it fits (None: a goal-conditioned Dict
    # observation's achieved_goal where there is one)
    reaching: Reached | None = None
    # it reads the entries of ONE observation by position, so it cannot read --history K's stack
    one_observation: bool = False
