"""CartpoleSwingup-v0: PETS' cart-pole swing-up (Chua et al. 2018), bundled with motorlab.

The model (cartpole_swingup.xml) is mbrl-lib's PETS cart-pole (mbrl/env/pets_cartpole.py and
assets/cartpole.xml): a cart on a rail (slide joint, range +-2.5 m), a pole of length 0.6 m on an
unactuated hinge, joint damping 1, a motor on the cart (gear 100, control in [-3, 3]), RK4 with a
0.02 s timestep and a frame skip of 2: one control step is 0.04 s, an episode 200 steps (8 s).
The only change is the angle's origin: here 0 is upright (PETS draws the pole down, so its 0 hangs).

Reset: the pole hangs down, angle pi, cart at 0, at rest, plus N(0, 0.1^2) noise on both positions
and both speeds (PETS' reset noise). Episodes never terminate; the time limit (200 steps) truncates.

Observation (5, float64): cart position x, sin and cos of the pole's angle theta (0 upright),
cart velocity, pole angular velocity. The pole's tip is at (x + l sin theta, l cos theta) from the
rail, l = 0.6.

Reward (PETS'): exp(-|tip - (0, l)|^2 / l^2) - 0.01 |a|^2, the tip read from the observation after
the step: near 1 with the pole upright above the rail's centre, exp(-4) ~ 0.018 hanging down there.
It is a function of the next observation and the action alone; motorlab.dynamics.planner_rewards'
`cartpole_swingup` computes it in torch with the same arithmetic, for the planner.

Importing this module imports MuJoCo; registering the id does not (motorlab.envs registers it
with this module's class named as a string).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces, utils
from gymnasium.envs.mujoco import MujocoEnv

__all__ = ["CartpoleSwingup", "ENV_ID", "EPISODE_STEPS", "POLE_LENGTH", "ACTION_COST", "reward"]

ENV_ID = "CartpoleSwingup-v0"
EPISODE_STEPS = 200
POLE_LENGTH = 0.6  # m, hinge to tip
ACTION_COST = 0.01
RESET_NOISE = 0.1  # std of the reset noise on positions and speeds (PETS')
FRAME_SKIP = 2  # x 0.02 s timestep: 0.04 s per control step
MODEL = Path(__file__).with_name("cartpole_swingup.xml")


def reward(next_obs: np.ndarray, action: np.ndarray) -> np.ndarray:
    """The env's reward from the observation after the step and the action, batched over any leading
    dims: (..., 5), (..., 1) -> (...). The same arithmetic, in the same order, as the torch version."""
    length = POLE_LENGTH
    dx = next_obs[..., 0] + length * next_obs[..., 1]  # tip minus target, along the rail
    dz = length * next_obs[..., 2] - length  # and up
    return np.exp(-(dx * dx + dz * dz) / (length * length)) - ACTION_COST * (action * action).sum(-1)


class CartpoleSwingup(MujocoEnv, utils.EzPickle):
    """PETS' cart-pole swing-up; see the module's docstring for its exact definition."""

    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 25}

    def __init__(self, render_mode: str | None = None, width: int = 480, height: int = 480,
                 camera_name: str | None = None, camera_id: int | None = None, **kwargs: Any):
        utils.EzPickle.__init__(self, render_mode, width, height, camera_name, camera_id, **kwargs)
        if camera_name is None and camera_id is None:
            camera_name = "side"  # the whole rail, from the side
        observation_space = spaces.Box(-np.inf, np.inf, (5,), np.float64)
        MujocoEnv.__init__(self, str(MODEL), FRAME_SKIP, observation_space=observation_space,
                           render_mode=render_mode, width=width, height=height, camera_name=camera_name,
                           camera_id=camera_id, **kwargs)

    def _get_obs(self) -> np.ndarray:
        x, theta = self.data.qpos
        x_dot, theta_dot = self.data.qvel
        return np.array([x, np.sin(theta), np.cos(theta), x_dot, theta_dot], dtype=np.float64)

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        self.do_simulation(action, self.frame_skip)
        obs = self._get_obs()
        r = float(reward(obs, action))
        if self.render_mode == "human":
            self.render()
        return obs, r, False, False, {}

    def reset_model(self) -> np.ndarray:
        qpos = np.array([0.0, np.pi]) + self.np_random.normal(0.0, RESET_NOISE, self.model.nq)
        qvel = self.np_random.normal(0.0, RESET_NOISE, self.model.nv)
        self.set_state(qpos, qvel)
        return self._get_obs()
