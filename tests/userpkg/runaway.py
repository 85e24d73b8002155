"""A simulation that diverges on some episodes, as a fragile MuJoCo body does: its state runs away
(x10 a step) for a few steps and then turns non-finite, which motorlab's NumericalGuard flags as a
numerical fault. `fault_at` maps a reset seed (as text) to the step where the run-away starts."""

import gymnasium as gym
import numpy as np

RUN_UP = 4  # steps of run-away before the state is no longer finite


class Runaway(gym.Env):
    metadata = {"render_modes": []}
    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self, fault_at: dict[str, int] | None = None):
        self.fault_at = {int(k): v for k, v in (fault_at or {}).items()}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.start = self.fault_at.get(seed)
        self.t, self.x = 0, np.array([float(self.np_random.uniform(-0.5, 0.5)), 0.0])
        return self.x.copy(), {}

    def step(self, action):
        self.t += 1
        self.x = self.x + 0.1 * np.array([self.x[1], float(np.clip(action[0], -1, 1))])
        if self.start is not None and self.t >= self.start:
            self.x = self.x * 10.0 + 1.0  # running away
            if self.t >= self.start + RUN_UP:
                self.x = np.array([np.inf, np.nan])
        return self.x.copy(), -float(self.x @ self.x) if np.isfinite(self.x).all() else np.nan, False, False, {}


gym.register("Runaway-v0", entry_point=Runaway, max_episode_steps=12)
