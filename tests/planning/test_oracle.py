"""The oracle (motorlab.planning.oracle): CEM planning on a copy of the true simulator scores an action
sequence exactly as stepping the env does, leaves the controlled env alone, balances the pendulum and
reaches Reacher's target far better than random actions."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motorlab.envs import EnvConfig, make_env
from motorlab.envs.disturbances import mujoco_model_data
from motorlab.errors import MotorlabError
from motorlab.planning.oracle import OracleResult, SimulatorScorer, oracle_episodes, physics_state, set_physics_state

PENDULUM, REACHER = "InvertedPendulum-v5", "Reacher-v5"


def stepped_return(env_id: str, state: np.ndarray, actions: np.ndarray) -> tuple[float, float]:
    """A fresh env put into `state` and stepped with `actions`: the return up to and including the step
    that terminates, and the sum of every step's reward (the steps after the end counted too)."""
    env = make_env(EnvConfig(id=env_id), shaped=False)
    env.reset(seed=123)  # another episode's start: the state set below decides
    set_physics_state(env, state)
    rewards, ended = [], None
    for t, action in enumerate(actions):
        _, reward, terminated, _, _ = env.step(action)
        rewards.append(reward)
        if terminated and ended is None:
            ended = t
    env.close()
    masked = 0.0
    for reward in rewards[:None if ended is None else ended + 1]:
        masked += reward
    return masked, float(sum(rewards))


def start_state(env_id: str, steps: int, seed: int = 0):
    """An env `steps` random steps into an episode, and its physics state."""
    env = make_env(EnvConfig(id=env_id), shaped=False)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    for _ in range(steps):
        env.step(env.action_space.sample())
    return env, physics_state(env)


def score(scorer: SimulatorScorer, state: np.ndarray, actions: np.ndarray) -> np.ndarray:
    states = torch.from_numpy(state)[None].repeat(len(actions), 1)
    return scorer(states, torch.from_numpy(actions), torch.zeros((len(actions), 0))).numpy()


def test_the_scorer_returns_what_stepping_the_env_returns_the_end_paid_what_follows_not():
    env, state = start_state(PENDULUM, 0)
    # +3, +3 then -3 x 4 from seed 0's start: the pole passes 0.2 rad at the third step (the end,
    # paid 0) and comes back up three steps later (reward 1 again, which must not count)
    fall = np.array([3.0] * 2 + [-3.0] * 4 + [0.0] * 9, dtype=np.float32)[:, None]
    rng = np.random.default_rng(0)
    plans = np.stack([fall, np.zeros_like(fall), *rng.uniform(-3, 3, (4, 15, 1)).astype(np.float32)])
    scorer = SimulatorScorer(PENDULUM)
    got = score(scorer, state, plans)
    expected = [stepped_return(PENDULUM, state, plan) for plan in plans]
    assert got.tolist() == [masked for masked, _ in expected]  # exactly
    assert expected[0] == (2.0, 7.0)  # the falling sequence: terminated, then rewarded again
    assert got[1] == 15.0  # doing nothing keeps it up for the horizon

    env, state = start_state(REACHER, 7)  # mid-episode, a float reward: equal to the last bit
    plans = rng.uniform(-1, 1, (5, 15, 2)).astype(np.float32)
    got = score(SimulatorScorer(REACHER), state, plans)
    assert got.tolist() == [stepped_return(REACHER, state, plan)[0] for plan in plans]
    assert len(set(got.tolist())) == len(plans)


def test_scoring_leaves_the_controlled_env_as_it_was():
    env, state = start_state(REACHER, 5)
    scorer = SimulatorScorer(REACHER)
    assert scorer.data is not mujoco_model_data(env)[1]
    qpos = env.unwrapped.data.qpos.copy()
    score(scorer, state, np.random.default_rng(1).uniform(-1, 1, (20, 10, 2)).astype(np.float32))
    assert np.array_equal(physics_state(env), state)
    assert np.array_equal(env.unwrapped.data.qpos, qpos)
    with pytest.raises(MotorlabError, match="float64"):  # a float32 state would not be the env's
        scorer(torch.from_numpy(state)[None].float(), torch.zeros((1, 3, 2)), torch.zeros((1, 0)))


def random_episode(env, seed: int) -> tuple[int, float]:
    """One episode of uniformly random actions (the env and its action space seeded with `seed`): its steps and return."""
    env.reset(seed=seed)
    env.action_space.seed(seed)
    steps, total, done = 0, 0.0, False
    while not done:
        _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        steps, total, done = steps + 1, total + reward, terminated or truncated
    return steps, total


def test_the_oracle_balances_the_pendulum_that_random_actions_drop():
    cfg = EnvConfig(id=PENDULUM, kwargs={"max_episode_steps": 200})
    # The pendulum pays 1 per step upright, so candidates differ only once a fall lies within the horizon;
    # a small budget needs many elites (the mean of tied elites jitters less) to keep it up for 200 steps.
    result = oracle_episodes(cfg, 2, [0, 1], horizon=20, population=30, iterations=2, elites=15)
    assert isinstance(result, OracleResult)
    assert result.returns.tolist() == [200.0, 200.0] and result.lengths.tolist() == [200, 200]
    assert len(result.plan_ms) == 400 and (result.plan_ms > 0).all()
    settings = (result.horizon, result.population, result.iterations, result.elites, result.seeds)
    assert settings == (20, 30, 2, 15, (0, 1))
    env = make_env(cfg, shaped=False)
    for seed in (0, 1):
        assert random_episode(env, seed)[0] < 20


def test_the_oracle_reaches_far_better_than_random_actions_on_reacher():
    result = oracle_episodes(REACHER, 2, [0, 1], horizon=8, population=20, iterations=2, elites=5)
    env = make_env(EnvConfig(id=REACHER), shaped=False)
    random_returns = [random_episode(env, seed)[1] for seed in (0, 1)]
    assert result.lengths.tolist() == [50, 50]
    assert result.returns.mean() > 0.5 * np.mean(random_returns)  # less than half the distance and effort


def test_the_oracle_refuses_what_a_copy_of_the_simulation_cannot_reproduce():
    with pytest.raises(MotorlabError, match="--delay"):
        oracle_episodes(EnvConfig(id=PENDULUM, delay=0.2), 1, [0])
    with pytest.raises(MotorlabError, match="one reset seed per episode"):
        oracle_episodes(PENDULUM, 2, [0])
