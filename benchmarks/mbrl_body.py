"""The env a user would write, for benchmarks/mbrl.py: a MuJoCo body Gymnasium does not ship.

VerticalArmReach-v0: the two-link arm of mbrl_body.xml in the vertical plane, gravity on,
hanging down at the start (a little noise on angles and speeds); two motors (actions in
[-1, 1], gear 2 N m) must lift the tip to a fixed target above and beside the shoulder and
hold it there against gravity. 150 control steps of 0.02 s; never terminates.

Observation (8): cos and sin of the two joint angles, the two joint speeds, tip - target
(x, z). Reward: -|tip - target| - 0.01 |action|^2, a function of (obs, action, next_obs)
alone, so `reward` below, batched in torch, is the env's reward exactly.

Importing this module registers the env: use it as "mbrl_body:VerticalArmReach-v0" and its
reward as "mbrl_body:reward" (benchmarks/ on sys.path, as when running benchmarks/mbrl.py).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from gymnasium.envs.mujoco import MujocoEnv

ENV_ID = "VerticalArmReach-v0"
EPISODE_STEPS = 150
ACTION_COST = 0.01


class VerticalArmReach(MujocoEnv):
    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 50}

    def __init__(self, **kwargs):
        obs = gym.spaces.Box(-np.inf, np.inf, (8,), np.float64)
        MujocoEnv.__init__(self, str(Path(__file__).with_name("mbrl_body.xml")), 2, observation_space=obs,
                           default_camera_config={"distance": 1.5, "elevation": 0.0, "azimuth": 90.0}, **kwargs)

    def _obs(self) -> np.ndarray:
        q, v = self.data.qpos, self.data.qvel
        tip = self.data.site("tip").xpos - self.data.site("target").xpos
        return np.concatenate([np.cos(q), np.sin(q), v, tip[[0, 2]]])

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        obs_before = self._obs()
        self.do_simulation(action, self.frame_skip)
        obs = self._obs()
        reward = float(reward_np(obs_before, action, obs))
        if self.render_mode == "human":
            self.render()
        return obs, reward, False, False, {}

    def reset_model(self) -> np.ndarray:
        qpos = self.init_qpos + self.np_random.uniform(-0.1, 0.1, self.model.nq)
        qvel = self.init_qvel + self.np_random.uniform(-0.1, 0.1, self.model.nv)
        self.set_state(qpos, qvel)
        return self._obs()


def reward_np(obs: np.ndarray, action: np.ndarray, next_obs: np.ndarray) -> np.ndarray:
    """The env's reward (numpy): the same arithmetic, in the same order, as `reward`. hypot, not
    sqrt of a sum of squares: torch.sqrt on CPU is not always correctly rounded (1 ulp off numpy's),
    hypot agrees bit for bit."""
    d = next_obs[..., 6:8]
    return -np.hypot(d[..., 0], d[..., 1]) - ACTION_COST * (action * action).sum(-1)


def reward(obs: torch.Tensor, action: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
    """The env's reward, batched over any leading dims: (..., 8), (..., 2), (..., 8) -> (...)."""
    d = next_obs[..., 6:8]
    return -torch.hypot(d[..., 0], d[..., 1]) - ACTION_COST * (action * action).sum(-1)


gym.register(ENV_ID, entry_point=VerticalArmReach, max_episode_steps=EPISODE_STEPS)
