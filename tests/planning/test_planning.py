"""What makes MPC learn at PETS' level: planning on the probability of ending (an alive reward),
iCEM's coloured noise, the model's measured open-loop error, and the loop's budgets."""

from __future__ import annotations

import dataclasses
import json

import gymnasium as gym
import numpy as np
import pytest
import torch

from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.open_loop import rollout_error
from motorlab.dynamics.planner_rewards import inverted_pendulum_termination
from motorlab.dynamics.train import fit_model
from motorlab.planning.mbrl import RoundRecord, reached
from motorlab.planning.mpc import EndProbability, end_spread
from motorlab.planning.mpc_episodes import build_policy
from motorlab.planning.planners.base import colored_noise

IP = "InvertedPendulum-v5"


@pytest.fixture(scope="module")
def ip_fit():
    """A 3-member deterministic ensemble of the pendulum, fit on 200 random episodes (~1,500 steps)."""
    data = collect_transitions(IP, 200, workers=1, seed=0, progress=False)
    model, _ = fit_model(data, epochs=60, ensemble=3, batch_size=64, seed=0, progress=False)
    return data, model


# ---- coloured noise ------------------------------------------------------------------------------


@pytest.mark.parametrize("beta", [0.0, 1.0, 2.0])
def test_colored_noise_has_unit_variance_and_is_smoother_the_redder(beta):
    x = colored_noise((4000, 30, 2), beta, torch.Generator().manual_seed(0))
    assert x.shape == (4000, 30, 2)
    assert abs(float(x.mean())) < 0.02 and 0.9 < float(x.std()) < 1.25
    lag1 = float(torch.corrcoef(torch.stack([x[:, :-1].flatten(), x[:, 1:].flatten()]))[0, 1])
    # white noise: neighbours independent; 1/f and 1/f^2: ever more alike (iCEM's smooth sequences)
    assert {0.0: abs(lag1) < 0.03, 1.0: 0.4 < lag1 < 0.75, 2.0: lag1 > 0.8}[beta]


def test_colored_noise_is_repeatable_from_the_seed():
    a, b = (colored_noise((3, 10, 1), 2.0, torch.Generator().manual_seed(5)) for _ in range(2))
    assert torch.equal(a, b)


# ---- the probability of ending --------------------------------------------------------------------


def test_end_probability_rises_towards_the_boundary_by_the_models_error():
    drift = np.array([[0.0, 0.05, 0.0, 0.0]] * 3)  # the pole's angle may be 0.05 rad off, every step ahead
    p_end = EndProbability(inverted_pendulum_termination, drift, draws=4000)
    angles = torch.tensor([0.0, 0.1, 0.2, 0.3])
    nxt = torch.zeros(4, 1, 4)
    nxt[:, 0, 1] = angles
    p = p_end(torch.zeros(4, 1, 4), torch.zeros(4, 1, 1), nxt, torch.zeros(4, 1, 0))[:, 0]
    # P(|angle + N(0, 0.05^2)| > 0.2): ~0 upright, ~2.3% at 0.1 rad, ~50% on the boundary, ~98% beyond
    assert p[0] < 0.002 and 0.01 < p[1] < 0.04 and 0.45 < p[2] < 0.55 and p[3] > 0.96
    exact = EndProbability(inverted_pendulum_termination, np.zeros((3, 4)), draws=8)
    assert exact(torch.zeros(4, 1, 4), torch.zeros(4, 1, 1), nxt, torch.zeros(4, 1, 0))[:, 0].tolist() == [0, 0, 0, 1]


def test_the_models_open_loop_error_is_measured_at_fit_time_and_grows_with_the_steps(ip_fit):
    data, model = ip_fit
    drift = np.asarray(model.meta["rollout_error"])
    assert drift.shape == (50, 4) and np.isfinite(drift).all() and (drift >= 0).all()
    assert (drift[9] > drift[0]).all()  # ten steps of feeding it its own predictions drift further than one
    assert rollout_error(model, data, np.array([], int)) is None
    again = rollout_error(model, data, np.arange(len(data)), seed=0)
    assert np.allclose(again, rollout_error(model, data, np.arange(len(data)), seed=0))


def test_the_open_loop_error_is_not_ruled_by_a_few_rows_no_model_predicts(ip_fit):
    """Like a cart hitting the end of its rail: 2% of the rows jump 1 rad in pole angle. The spread is
    a normal's sigma from the median absolute error, so it stays where the other 98% put it; a root
    mean square would be at least sqrt(0.02) x 1 rad = 0.14 rad."""
    data, model = ip_fit
    rows = np.arange(len(data))
    clean = rollout_error(model, data, rows, seed=0)
    jumps = np.random.default_rng(0).choice(rows, size=len(rows) // 50, replace=False)
    next_states = data.next_states.copy()
    next_states[jumps, 1] += 1.0
    spread = rollout_error(model, dataclasses.replace(data, next_states=next_states), rows, seed=0)
    assert spread[0, 1] < 0.05 and spread[0, 1] <= 1.2 * clean[0, 1] + 1e-4
    np.testing.assert_allclose(spread[:, [0, 2, 3]], clean[:, [0, 2, 3]])  # only the angle's truth moved


def test_the_open_loop_error_is_saved_with_the_model(ip_fit, tmp_path):
    from motorlab.dynamics.model import load_model

    _, model = ip_fit
    model.save(tmp_path / "m")
    assert json.loads((tmp_path / "m" / "model.json").read_text())["rollout_error"] == model.meta["rollout_error"]
    assert load_model(tmp_path / "m").meta["rollout_error"] == model.meta["rollout_error"]


def test_the_end_spread_is_the_models_error_with_a_margin_as_a_floor(ip_fit):
    _, model = ip_fit
    drift = np.asarray(model.meta["rollout_error"])
    assert np.array_equal(end_spread(model, drift, 0.0), drift)
    typical = model.delta_norm.std.numpy().astype(np.float64)
    spread = end_spread(model, drift, 0.5)
    floor = 0.5 * typical[None] * np.sqrt(np.arange(1, 51))[:, None]  # half a typical step's change, a random walk
    np.testing.assert_allclose(spread, np.maximum(drift, floor))
    assert (spread >= drift).all() and (spread[9] > spread[0]).all()
    assert np.array_equal(end_spread(object(), drift, 0.5), drift)  # no normalizer (not a ForwardModel): no floor


def _steps_up(model, draws: int, seeds=range(10, 16), cap: int = 300, margin: float = 0.0) -> list[int]:
    env = gym.make(IP)
    policy = build_policy(env, IP, model, "cem", seed=0, termination_draws=draws, horizon=15, population=100,
                          iterations=3, elites=10, termination_margin=margin)
    lengths = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        policy.reset(1)
        steps, done = 0, False
        while not done and steps < cap:
            obs, _, terminated, truncated, _ = env.step(policy.act(obs[None])[0])
            steps, done = steps + 1, terminated or truncated
        lengths.append(steps)
    env.close()
    return lengths


def test_planning_on_the_probability_of_ending_keeps_the_pendulum_up_longer(ip_fit):
    """Same model, same seeds, same optimizer: only how a predicted fall is scored differs. With a
    yes/no end every candidate that survives the horizon scores the same, and CEM drifts among them;
    with the draws, among those that stay clear of the end by the model's error, at least half a
    typical step's change x sqrt(t + 1) t steps ahead (the default margin, 0.5)."""
    _, model = ip_fit
    plain, aware = _steps_up(model, 0), _steps_up(model, 16, margin=0.5)
    assert np.mean(aware) > 1.5 * np.mean(plain), (plain, aware)
    # the margin does most of it: spread by the model's (robust) error alone, the draws barely reach
    # past a predicted path (measured: plain 68.3, draws 77.0, with the margin 130.2 steps up on average)
    unfloored = _steps_up(model, 16)
    assert np.mean(plain) < np.mean(unfloored) < np.mean(aware) / 1.3, (plain, unfloored, aware)


# ---- the loop's stopping rules ----------------------------------------------------------------------


def _record(mean: float | None, worst: float | None) -> RoundRecord:
    return RoundRecord(round=1, env_steps=100, episodes=1, collect_return_mean=0.0, eval_return_mean=mean,
                       eval_return_std=0.0, eval_return_min=worst, valid_mse=None, valid_mse_first=None,
                       plan_ms_median=None, disagreement_mean=None, collect_seconds=0, fit_seconds=0, eval_seconds=0)


def test_until_return_reads_the_mean_or_every_episode():
    r = _record(1000.0, 640.0)  # nine episodes held 1000 steps, one fell at 640
    assert reached(r, 1000.0) and not reached(r, 1000.0, every_episode=True)
    assert reached(_record(1000.0, 1000.0), 1000.0, every_episode=True)
    assert not reached(r, None) and not reached(_record(None, None), 0.0)
