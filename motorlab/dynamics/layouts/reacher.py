"""`--state reacher`: Reacher's 8 numbers (cos, sin, joint speeds, fingertip x-y), the target the goal (the reference notebook's)."""

from __future__ import annotations

import numpy as np

from motorlab.dynamics.layouts.base import LayoutSpec
from motorlab.dynamics.state import KeySlice, Reached, StateLayout
from motorlab.errors import MotorlabError

LABELS = ("cos q1", "cos q2", "sin q1", "sin q2", "dq1", "dq2", "tip x", "tip y")
FINGERTIP = Reached((6, 7), "tip", "fingertip", "m")


def _state(obs: np.ndarray) -> np.ndarray:
    # obs: cos(2), sin(2), target xy (2), qvel (2), fingertip - target (2 in v5, 3 in v4)
    tip = obs[..., 8:10] + obs[..., 4:6]
    return np.concatenate([obs[..., 0:4], obs[..., 6:8], tip], axis=-1)


REACHER = StateLayout("reacher", LABELS, ("target x", "target y"), _state, lambda obs: obs[..., 4:6],
                      reaching=FINGERTIP)


def build(env_id: str, obs_dim: int, keys: tuple[KeySlice, ...]) -> StateLayout:
    if obs_dim not in (10, 11) or keys:
        raise MotorlabError(f"the reacher state layout needs Reacher's 10 (v5) or 11 (v4) observations, "
                            f"not {obs_dim}; use --state observation for {env_id}.")
    return REACHER


LAYOUT = LayoutSpec(build, reaching=FINGERTIP, one_observation=True)
