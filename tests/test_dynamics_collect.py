"""Reacher rollouts straight in MuJoCo vs Gymnasium's env, and the reacher state layout."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from motorlab.dynamics.reacher_sim import rollout_reacher, sample_initial_states
from motorlab.dynamics.state import layout_for
from motorlab.errors import MotorlabError


def gym_rollout(env, qpos0, qvel0, actions):
    obs, rewards = [], []
    env.reset(seed=0)
    env.unwrapped.set_state(qpos0, qvel0)
    obs.append(env.unwrapped._get_obs())
    for a in actions:
        o, r, *_ = env.step(a)
        obs.append(o)
        rewards.append(r)
    return np.array(obs), np.array(rewards), env.unwrapped.data.qpos[1]


@pytest.mark.parametrize("env_id", ["Reacher-v5", "Reacher-v4"])
def test_rollout_matches_gymnasium(env_id):
    env = gym.make(env_id)
    rng = np.random.default_rng(3)
    qpos, qvel = sample_initial_states(env, 12, rng)
    actions = rng.uniform(-1, 1, size=(12, 50, 2))
    obs, rewards = rollout_reacher(env, qpos, qvel, actions, threads=2)
    assert obs.shape == (12, 51, env.observation_space.shape[0]) and rewards.shape == (12, 50)
    joint = np.r_[0:8]  # cos, sin, target, joint velocities: from qpos/qvel, bit-identical
    for e in range(12):
        g_obs, g_rew, _ = gym_rollout(env, qpos[e], qvel[e], actions[e])
        np.testing.assert_array_equal(obs[e][:, joint], g_obs[:, joint])
        # fingertip: exact kinematics vs RK4's last stage (see reacher_sim); mm at the elbow limit
        tip = np.abs(obs[e][:, 8:] - g_obs[:, 8:]).max(axis=1)
        near_limit = np.abs(np.arctan2(g_obs[:, 3], g_obs[:, 1])) > 2.9
        assert tip[~near_limit].max(initial=0) < 2e-4 and tip.max() < 5e-3
        assert np.abs(rewards[e] - g_rew).max() < 5e-3


def test_initial_states_follow_the_env_reset():
    env = gym.make("Reacher-v5")
    qpos, qvel = sample_initial_states(env, 5000, np.random.default_rng(0))
    goal = qpos[:, 2:]
    assert (np.linalg.norm(goal, axis=1) < 0.2).all() and np.abs(goal).max() > 0.18
    assert np.abs(qpos[:, :2]).max() <= 0.1 and (qvel[:, 2:] == 0).all() and np.abs(qvel).max() <= 0.005
    g = np.array([env.reset(seed=s)[0][4:6] for s in range(300)])
    assert abs(np.linalg.norm(g, axis=1).mean() - np.linalg.norm(goal, axis=1).mean()) < 0.01


def test_reacher_layout():
    env = gym.make("Reacher-v5")
    obs, _ = env.reset(seed=1)
    layout = layout_for("Reacher-v5", 10)
    state = layout.state(obs[None])[0]
    assert layout.size == 8 and state.shape == (8,)
    np.testing.assert_allclose(state[6:], env.unwrapped.get_body_com("fingertip")[:2], atol=1e-12)
    np.testing.assert_array_equal(layout.goal(obs), obs[4:6])
    assert layout_for("Pendulum-v1", 3).size == 3 and layout_for("Pendulum-v1", 3).goal(np.zeros(3)).shape == (0,)
    with pytest.raises(MotorlabError, match="--state observation"):
        layout_for("Pendulum-v1", 3, "reacher")
