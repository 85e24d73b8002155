"""CartpoleSwingup-v0, PETS' cart-pole swing-up bundled with motorlab: its reset (hanging down), its
200-step episodes, its reward, the planner's torch reward equal to it, and its catalogue entry."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch

from motorlab.dynamics.planner_rewards import cartpole_swingup, resolve_task
from motorlab.envs import EnvConfig, facts, make_env
from motorlab.envs.cartpole_swingup import ACTION_COST, POLE_LENGTH

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

ENV_ID = "CartpoleSwingup-v0"


@pytest.fixture
def env():
    env = make_env(EnvConfig(id=ENV_ID))
    yield env
    env.close()


def tip(obs: np.ndarray) -> np.ndarray:
    """The pole's tip (x, z) from an observation (x, sin, cos, x', theta')."""
    return np.array([obs[0] + POLE_LENGTH * obs[1], POLE_LENGTH * obs[2]])


def test_registering_it_does_not_import_its_module():
    code = ("import sys, gymnasium as gym, motorlab.envs; spec = gym.spec('CartpoleSwingup-v0'); "
            "print(spec.entry_point, spec.max_episode_steps, 'motorlab.envs.cartpole_swingup' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["motorlab.envs.cartpole_swingup:CartpoleSwingup", "200", "False"]


def test_the_pole_starts_hanging_down(env):
    for seed in range(20):
        obs, _ = env.reset(seed=seed)
        qpos = env.unwrapped.data.qpos
        assert abs(qpos[1] - np.pi) < 0.5, seed  # angle pi plus N(0, 0.1^2) noise
        assert np.allclose(obs[1:3], [np.sin(qpos[1]), np.cos(qpos[1])]) and obs[2] < -0.8
        assert tip(obs)[1] < 0, seed  # the tip below the rail
    a, _ = env.reset(seed=3)
    b, _ = env.reset(seed=3)
    np.testing.assert_array_equal(a, b)  # the noise comes from the reset seed


def test_an_episode_is_200_steps_of_0_04_s_and_never_terminates(env):
    assert env.unwrapped.dt == pytest.approx(0.04)
    assert env.observation_space.shape == (5,) and env.action_space.shape == (1,)
    np.testing.assert_array_equal(env.action_space.low, [-3.0])
    np.testing.assert_array_equal(env.action_space.high, [3.0])
    env.reset(seed=0)
    env.action_space.seed(0)
    for step in range(1, 201):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        assert not terminated
        assert truncated == (step == 200)


def test_the_reward_is_the_tips_closeness_to_upright_minus_the_action_cost(env):
    env.reset(seed=0)
    sim = env.unwrapped
    sim.set_state(np.array([0.0, 0.0]), np.zeros(2))  # upright at the rail's centre, at rest
    obs, r, *_ = env.step(np.zeros(1))
    assert r == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(tip(obs), [0.0, POLE_LENGTH], atol=1e-4)
    sim.set_state(np.array([0.0, 0.0]), np.zeros(2))
    _, r_pushed, *_ = env.step(np.array([2.0]))
    assert r_pushed == pytest.approx(1.0 - ACTION_COST * 4.0, abs=1e-3)
    sim.set_state(np.array([0.0, np.pi]), np.zeros(2))  # hanging down: the tip 2 l below the target
    _, r_down, *_ = env.step(np.zeros(1))
    assert r_down == pytest.approx(np.exp(-4.0), abs=1e-6)


def transitions(episodes: int = 3):
    env = gym.make(ENV_ID)
    env.action_space.seed(1)
    states, actions, next_states, rewards = [], [], [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=episode)
        done = False
        while not done:
            action = env.action_space.sample()
            next_obs, reward, terminated, truncated, _ = env.step(action)
            states.append(obs), actions.append(action), next_states.append(next_obs), rewards.append(reward)
            obs, done = next_obs, terminated or truncated
    env.close()
    return [np.array(x, dtype=np.float64) for x in (states, actions, next_states, rewards)]


def test_the_planners_reward_is_the_envs():
    s, a, n, rewards = transitions()
    assert len(rewards) == 600 and rewards.max() > rewards.min()
    task = resolve_task(ENV_ID, "observation", 5, 1)
    assert task.reward is cartpole_swingup and task.reward_source == "builtin" and task.termination is None
    st, at, nt = (torch.as_tensor(x) for x in (s, a, n))
    goal = torch.zeros(len(s), 0, dtype=torch.float64)
    batched = task.reward(st, at, nt, goal)
    assert batched.dtype == torch.float64 and batched.shape == (600,)
    np.testing.assert_allclose(batched.numpy(), rewards, rtol=0, atol=1e-12)
    leading = task.reward(st.reshape(20, 30, 5), at.reshape(20, 30, 1), nt.reshape(20, 30, 5), goal.reshape(20, 30, 0))
    np.testing.assert_allclose(leading.reshape(-1).numpy(), rewards, rtol=0, atol=1e-12)  # any leading dims
    for i in range(0, 600, 37):  # one at a time
        one = task.reward(st[i], at[i], nt[i], goal[i])
        assert one.shape == () and abs(float(one) - rewards[i]) < 1e-12


def test_make_env_builds_it_and_the_catalogue_has_its_reward(env):
    assert env.spec.id == ENV_ID and env.spec.max_episode_steps == 200
    assert env.spec.reward_threshold == 170.0  # what counts as solved (the benchmark's threshold)
    f = facts(ENV_ID)
    [plan] = f.planning
    assert plan.layout == "observation" and plan.state_size == 5
    assert plan.reward == "motorlab.dynamics.planner_rewards:cartpole_swingup" and plan.termination is None
    assert f.max_return is None and len(f.obs_labels) == 5 and not f.falls


def test_it_renders_frames():
    env = make_env(EnvConfig(id=ENV_ID), render_mode="rgb_array")
    try:
        env.reset(seed=0)
        frame = env.render()
    finally:
        env.close()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8 and frame.std() > 0
