"""PID controller: default gains balance the pendulum; gain parsing; the D term uses dt."""

from __future__ import annotations

import numpy as np
import pytest

from motorlab.controllers.pid import PIDController, make_pid, parse_gains
from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.evaluation import evaluate
from motorlab.policies import load_policy

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


@pytest.mark.parametrize(
    "env_id, seed",
    [("InvertedPendulum-v5", 0), ("InvertedPendulum-v5", 1), ("InvertedPendulum-v5", 7), ("InvertedPendulum-v4", 0)],
)
def test_default_pid_reaches_max_return(env_id, seed):
    cfg = EnvConfig(id=env_id)
    env = make_env(cfg)
    pid = load_policy("pid", env, env_id)
    env.close()
    result = evaluate(pid, cfg, episodes=3, seed=seed)
    assert result.returns.shape == (3,)
    np.testing.assert_array_equal(result.returns, 1000.0)
    np.testing.assert_array_equal(result.lengths, 1000)
    assert result.success.all()


def test_zero_policy_fails_where_pid_succeeds():
    # The max-return check above means something: doing nothing drops the pole.
    cfg = EnvConfig()
    env = make_env(cfg)
    result = evaluate(load_policy("zero", env, cfg.id), cfg, episodes=3, seed=0)
    assert (result.returns < 1000).all() and not result.success.any()


@pytest.mark.parametrize(
    "text, expected",
    [
        ("kp=[1,20,0,0],kd=1;3;0;0", {"kp": [1.0, 20.0, 0.0, 0.0], "kd": [1.0, 3.0, 0.0, 0.0]}),
        ("kp=[1, 20, 0, 0], ki=0, kd=[1,3,0,0]",
         {"kp": [1.0, 20.0, 0.0, 0.0], "ki": [0.0], "kd": [1.0, 3.0, 0.0, 0.0]}),
        ("kd=0.5", {"kd": [0.5]}),
        ("", {}),
    ],
)
def test_parse_gains(text, expected):
    assert parse_gains(text) == expected


@pytest.mark.parametrize("text", ["kx=[1,2]", "kp=[a,b,c,d]", "kp=[1,2] garbage"])
def test_parse_gains_rejects_bad_text(text):
    with pytest.raises(MotorlabError):
        parse_gains(text)


def test_make_pid_fills_defaults_and_broadcasts_scalars():
    pid = make_pid("pid:kp=[2,30,0,0],ki=0.5", "InvertedPendulum-v5", 4, 0.04, [-3.0], [3.0])
    np.testing.assert_array_equal(pid.kp, [[2, 30, 0, 0]])
    np.testing.assert_array_equal(pid.ki, [[0.5, 0.5, 0.5, 0.5]])  # one number: every element
    np.testing.assert_array_equal(pid.kd, [[1, 3, 0, 0]])  # not given: the env's default


@pytest.mark.parametrize("spec", ["pid:kp=[1,20,0]", "pid:kd=[1,3,0,0,0]", "pid:ki=[1,2]"])
def test_wrong_number_of_gains_raises(spec):
    with pytest.raises(MotorlabError, match="4"):
        make_pid(spec, "InvertedPendulum-v5", 4, 0.04, [-3.0], [3.0])


def test_no_default_gains_for_unknown_env():
    with pytest.raises(MotorlabError, match="gains"):
        make_pid("pid", "Reacher-v5", 10, 0.02, [-1.0] * 2, [1.0] * 2)


def test_pid_rejects_observation_of_wrong_size():
    pid = make_pid("pid", "InvertedPendulum-v5", 4, 0.04, [-3.0], [3.0])
    with pytest.raises(MotorlabError):
        pid.act(np.zeros((1, 8)))


def test_pid_formula_by_hand():
    kp, ki, kd = np.array([1.0, -2.0]), np.array([0.5, 0.25]), np.array([0.1, 0.3])
    dt = 0.05
    pid = PIDController(kp, ki, kd, dt=dt, low=np.array([-np.inf]), high=np.array([np.inf]))
    rng = np.random.default_rng(0)
    errors = rng.normal(size=(6, 3, 2))  # 6 steps, a batch of 3 episodes, 2 observation elements
    integral = np.zeros((3, 2))
    prev = None
    for e in errors:
        integral += e * dt
        derivative = np.zeros_like(e) if prev is None else (e - prev) / dt  # no kick on the first step
        expected = e @ kp + integral @ ki + derivative @ kd
        np.testing.assert_allclose(pid.act(e)[:, 0], expected, rtol=1e-5)
        prev = e


def test_d_term_uses_env_dt():
    env_id = "InvertedPendulum-v5"
    env = make_env(EnvConfig(id=env_id))
    dt = env.unwrapped.dt
    assert dt == pytest.approx(0.04)
    kd = np.array([0.01, 0.02, 0.003, 0.004])
    pid = load_policy("pid:kp=0,ki=0,kd=[0.01,0.02,0.003,0.004]", env, env_id)
    assert pid.dt == dt
    obs0, _ = env.reset(seed=0)
    pid.reset(1)
    assert pid.act(obs0[None])[0, 0] == 0.0  # first step: no derivative kick
    obs1, *_ = env.step(np.array([1.0], dtype=np.float32))
    expected = float((obs1 - obs0) @ kd / dt)
    assert abs(expected) > 1e-3  # the check below is not trivially zero
    assert pid.act(obs1[None])[0, 0] == pytest.approx(np.clip(expected, -3, 3), rel=1e-5)


def test_pid_output_is_clipped_to_action_bounds():
    pid = make_pid("pid:kp=100,ki=0,kd=0", "InvertedPendulum-v5", 4, 0.04, [-3.0], [3.0])
    out = pid.act(np.array([[1.0, 1.0, 1.0, 1.0], [-1.0, -1.0, -1.0, -1.0]]))
    np.testing.assert_array_equal(out[:, 0], [3.0, -3.0])
    assert out.dtype == np.float32


def test_pid_batch_rows_are_independent():
    # Each evaluation episode is one row: a batch of two equals two single runs.
    rng = np.random.default_rng(1)
    seq = rng.normal(scale=0.05, size=(5, 2, 4))
    batched = make_pid("pid", "InvertedPendulum-v5", 4, 0.04, [-3.0], [3.0])
    rows = [make_pid("pid", "InvertedPendulum-v5", 4, 0.04, [-3.0], [3.0]) for _ in range(2)]
    for obs in seq:
        both = batched.act(obs)
        for i, single in enumerate(rows):
            np.testing.assert_allclose(both[i], single.act(obs[i:i + 1])[0], rtol=1e-6)

