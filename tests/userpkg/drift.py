"""A drifting point, declared to motorlab two ways (tests/envs/test_catalog.py): CatalogDrift-v0's
class carries its facts in metadata["motorlab"]; CatalogPlain-v0 is the same env without them. A module,
so that evaluation's worker processes (forkserver) import it and know the ids."""

import gymnasium as gym
import numpy as np


class Drift(gym.Env):
    """A point that drifts (drift x 0.1 per step) unless pushed back; |x| > 1 ends the episode."""

    metadata = {"render_modes": []}
    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    dt = 0.1

    def __init__(self, drift: float = 0.5):
        self.drift = drift

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.v = float(self.np_random.uniform(-0.5, 0.5)), 0.0
        return self._obs(), {}

    def _obs(self):
        return np.array([self.x, self.v])

    def step(self, action):
        self.v += 0.1 * (float(np.clip(action[0], -1, 1)) + self.drift)
        self.x += 0.1 * self.v
        return self._obs(), 1.0, abs(self.x) > 1, False, {"reached": abs(self.x) < 0.1, "solved": True}


class DeclaredDrift(Drift):
    metadata = {"render_modes": [], "motorlab": {"falls": True, "success_key": "reached", "success_mode": "final",
                                                 "max_return": 30}}


gym.register("CatalogDrift-v0", entry_point=DeclaredDrift, max_episode_steps=30)
gym.register("CatalogPlain-v0", entry_point=Drift, max_episode_steps=30)
