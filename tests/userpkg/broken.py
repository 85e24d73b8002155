"""Modules that go wrong the ways users' modules do: a bad import, bad spaces."""

import gymnasium as gym
import numpy as np


class WrongShape(gym.Env):
    """Observations that do not fit the space it declares."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(5, np.float32), {}

    def step(self, action):
        return np.zeros(5, np.float32), 0.0, False, False, {}


gym.register("WrongShape-v0", entry_point=WrongShape, max_episode_steps=10)
