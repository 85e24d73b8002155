"""Model-based control: least-squares ARX fit, companion form, LQR gain, learn_lqr."""

from __future__ import annotations

import numpy as np
import pytest

from motorlab.controllers.lqr import LQRPolicy, LQRSettings, companion_form, fit_linear_model, learn_lqr, lqr_gain
from motorlab.envs import EnvConfig
from motorlab.evaluation import evaluate

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def spectral_radius(M: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def test_fit_linear_model_recovers_known_system():
    rng = np.random.default_rng(0)
    nz, m, d, n = 6, 2, 4, 200
    A_true = rng.normal(size=(d, nz))
    B_true = rng.normal(size=(d, m))
    Z = rng.normal(size=(n, nz))
    U = rng.normal(size=(n, m))
    O_next = Z @ A_true.T + U @ B_true.T  # noiseless
    A, B, mse = fit_linear_model(Z, U, O_next, ridge=0.0)
    np.testing.assert_allclose(A, A_true, atol=1e-8)
    np.testing.assert_allclose(B, B_true, atol=1e-8)
    assert mse < 1e-16
    # The default ridge barely biases a well-conditioned fit.
    A, B, _ = fit_linear_model(Z, U, O_next)
    np.testing.assert_allclose(A, A_true, atol=1e-5)
    np.testing.assert_allclose(B, B_true, atol=1e-5)


def test_fit_linear_model_reports_noise_as_mse():
    rng = np.random.default_rng(1)
    Z, U = rng.normal(size=(2000, 3)), rng.normal(size=(2000, 1))
    noise = 0.1 * rng.normal(size=(2000, 3))
    O_next = Z @ np.eye(3) + U @ np.ones((1, 3)) + noise
    _, _, mse = fit_linear_model(Z, U, O_next)
    assert mse == pytest.approx(0.01, rel=0.15)


@pytest.mark.parametrize("obs_lags, act_lags", [(1, 0), (2, 1), (3, 2)])
def test_companion_form_reproduces_the_arx_recursion(obs_lags, act_lags):
    rng = np.random.default_rng(obs_lags * 10 + act_lags)
    d, m = 3, 2
    nz = d * obs_lags + m * act_lags
    A_top = 0.3 * rng.normal(size=(d, nz))
    B_top = rng.normal(size=(d, m))
    A, B = companion_form(A_top, B_top, obs_lags, act_lags)
    assert A.shape == (nz, nz) and B.shape == (nz, m)
    # Simulate o_{t+1} = sum_i A_i o_{t-i} + sum_j B_j u_{t-j} by hand, alongside z_{t+1} = A z_t + B u_t.
    obs = [rng.normal(size=d) for _ in range(obs_lags)]  # oldest first
    acts = [rng.normal(size=m) for _ in range(act_lags)]
    z = np.concatenate([*reversed(obs), *reversed(acts)]) if act_lags else np.concatenate(list(reversed(obs)))
    for _ in range(5):
        u = rng.normal(size=m)
        o_next = A_top @ z + B_top @ u
        obs.append(o_next)
        acts.append(u)
        z = A @ z + B @ u
        newest_obs = list(reversed(obs[-obs_lags:]))
        newest_acts = list(reversed(acts[-act_lags:])) if act_lags else []
        np.testing.assert_allclose(z, np.concatenate(newest_obs + newest_acts), atol=1e-12)


def test_lqr_gain_stabilizes_unstable_system():
    rng = np.random.default_rng(2)
    n, m = 4, 1
    A = rng.normal(size=(n, n))
    A *= 1.5 / spectral_radius(A)  # unstable: spectral radius 1.5
    B = rng.normal(size=(n, m))
    K = lqr_gain(A, B, np.eye(n), 0.1 * np.eye(m))
    assert K.shape == (m, n)
    assert spectral_radius(A) > 1.0
    assert spectral_radius(A - B @ K) < 1.0


def test_lqr_on_companion_form_stabilizes_unstable_arx_model():
    # An unstable second-order system observed through its output only: o_{t+1} = 2.2 o_t - 1.1 o_{t-1} + u_t.
    A_top = np.array([[2.2, -1.1, 0.0]])  # z = [o_t, o_{t-1}, u_{t-1}]
    B_top = np.array([[1.0]])
    A, B = companion_form(A_top, B_top, obs_lags=2, act_lags=1)
    assert spectral_radius(A) > 1.0
    Q = np.zeros((3, 3))
    Q[0, 0] = 1.0
    K = lqr_gain(A, B, Q, 0.1 * np.eye(1))
    assert spectral_radius(A - B @ K) < 1.0
    # And the batched LQRPolicy, run on the true system, drives the output to zero.
    policy = LQRPolicy(K=K, obs_dim=1, act_dim=1, obs_lags=2, act_lags=1,
                       low=np.array([-np.inf]), high=np.array([np.inf]))
    o_prev, o = np.ones((2, 1)), np.array([[1.0], [-0.5]])  # a batch of two episodes
    policy.reset(2)
    for _ in range(60):
        u = policy.act(o).astype(np.float64)
        o, o_prev = 2.2 * o - 1.1 * o_prev + u, o
    assert np.all(np.abs(o) < 1e-3)


def test_lqr_policy_round_trips_through_dict():
    rng = np.random.default_rng(3)
    p = LQRPolicy(K=rng.normal(size=(1, 9)), obs_dim=4, act_dim=1, obs_lags=2, act_lags=1,
                  low=np.array([-3.0]), high=np.array([3.0]))
    q = LQRPolicy.from_dict(p.to_dict())
    obs = rng.normal(scale=0.1, size=(3, 4))
    p.reset(3)
    q.reset(3)
    for _ in range(3):
        np.testing.assert_array_equal(p.act(obs), q.act(obs))


def test_learn_lqr_solves_inverted_pendulum_within_budget():
    updates = []

    def on_update(steps, policy, info):
        updates.append((steps, info["model_mse"]))
        return False

    budget = 300
    policy, steps = learn_lqr(EnvConfig(), LQRSettings(), timesteps=budget, seed=0, on_update=on_update)
    assert policy is not None
    assert steps == budget  # on_update never asked to stop
    assert [s for s, _ in updates] == [100, 200, 300]  # one refit per batch_steps
    assert all(np.isfinite(mse) and mse >= 0 for _, mse in updates)
    result = evaluate(policy, EnvConfig(), episodes=5, seed=123)
    np.testing.assert_array_equal(result.returns, 1000.0)


def test_learn_lqr_stops_when_asked():
    policy, steps = learn_lqr(EnvConfig(), LQRSettings(), timesteps=5000, seed=1,
                              on_update=lambda steps, policy, info: True)
    assert policy is not None and steps == LQRSettings().batch_steps
