"""A three-joint planar arm with motors reaching a target: a MuJoCo body Gymnasium does not have.

Importing this module registers ArmReach-v0 and ArmReachHeavy-v0 (the same arm, forearm 3x heavier).
"""

from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.envs.mujoco import MujocoEnv

XML = Path(__file__).with_name("arm.xml")


class ArmReach(MujocoEnv):
    metadata = {"render_modes": ["human", "rgb_array", "depth_array"], "render_fps": 50}

    def __init__(self, forearm_mass: float = 0.5, **kwargs):
        obs = gym.spaces.Box(-np.inf, np.inf, (8,), np.float64)  # joint angles, velocities, tip - target
        MujocoEnv.__init__(self, str(XML), 2, observation_space=obs, **kwargs)
        self.model.body_mass[self.model.body("forearm").id] = forearm_mass

    def _obs(self):
        tip = self.data.site("tip").xpos[:2] - self.data.site("target").xpos[:2]
        return np.concatenate([self.data.qpos, self.data.qvel, tip])

    def step(self, action):
        self.do_simulation(action, self.frame_skip)
        obs = self._obs()
        reward = -np.linalg.norm(obs[6:]) - 0.01 * np.square(action).sum()
        if self.render_mode == "human":
            self.render()
        return obs, reward, False, False, {}

    def reset_model(self):
        angle, radius = self.np_random.uniform(-np.pi, np.pi), self.np_random.uniform(0.1, 0.35)
        self.data.mocap_pos[0, :2] = radius * np.cos(angle), radius * np.sin(angle)  # a new target
        self.set_state(self.init_qpos + self.np_random.uniform(-0.1, 0.1, 3), self.init_qvel)
        return self._obs()


gym.register("ArmReach-v0", entry_point=ArmReach, max_episode_steps=100)
gym.register("ArmReachHeavy-v0", entry_point=ArmReach, max_episode_steps=100, kwargs={"forearm_mass": 1.5})
