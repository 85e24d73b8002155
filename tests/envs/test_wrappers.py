"""Env wrappers: low-pass delay math and resets, observation history, reward shaping,
and Gymnasium's env checker on every wrapper combination."""

from __future__ import annotations

import math
import textwrap
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from motorlab.controllers.pid import make_pid
from motorlab.envs import EnvConfig, LowPassDelay, make_env
from motorlab.envs.rewards import BUILTIN, resolve_reward
from motorlab.envs.wrappers import delay_alpha
from motorlab.errors import MotorlabError

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

ENV_ID = "InvertedPendulum-v5"
DT = 0.04  # InvertedPendulum's step dt
TAU = 0.08  # delay time constant used below: alpha = 0.04 / 0.08 = 0.5
ALPHA = DT / TAU
STEPS = 20


def plain_env() -> gym.Env:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(ENV_ID)


def balancing_actions(seed: int):
    """A generator of actions: PID on the true observation plus random noise, so that
    the pendulum stays up for the whole test while the actions vary step to step."""
    pid = make_pid("pid", ENV_ID, 4, DT, np.array([-3.0]), np.array([3.0]))
    pid.reset(1)
    rng = np.random.default_rng(seed)

    def next_action(true_obs: np.ndarray) -> np.ndarray:
        u = pid.act(true_obs[None])[0] + rng.uniform(-0.5, 0.5, size=1)
        return np.clip(u, -3.0, 3.0).astype(np.float32)

    return next_action


# ---- delay_alpha ---------------------------------------------------------------

def test_delay_alpha_is_dt_over_tau():
    assert delay_alpha(0.04, 0.2) == pytest.approx(0.2)
    assert delay_alpha(0.04, 0.08) == pytest.approx(0.5)
    assert 0 < delay_alpha(0.04, 0.0401) < 1


@pytest.mark.parametrize("tau", [0.04, 0.01, 0.0, -1.0, math.nan, math.inf, -math.inf])
def test_delay_alpha_rejects_out_of_range(tau):
    # tau <= dt gives alpha >= 1; tau <= 0, NaN and inf are not valid time constants.
    with pytest.raises(MotorlabError):
        delay_alpha(0.04, tau)


def test_make_env_rejects_bad_delay():
    with pytest.raises(MotorlabError, match="0.01"):
        make_env(EnvConfig(delay=0.01))
    with pytest.raises(MotorlabError):
        make_env(EnvConfig(delay=-1.0))


def test_delay_rejects_unknown_target():
    with pytest.raises(MotorlabError, match="sensor"):
        LowPassDelay(plain_env(), TAU, on="sensor")


# ---- actuation delay -----------------------------------------------------------

def test_action_delay_follows_low_pass_recursion_and_restarts_at_zero():
    env = LowPassDelay(plain_env(), TAU, on="action")
    assert env.alpha == pytest.approx(ALPHA)
    twin = plain_env()  # receives the hand-filtered action: must end in the same state
    for episode, seed in enumerate([3, 4]):  # the second reset checks the restart
        obs, _ = env.reset(seed=seed)
        true_obs, _ = twin.reset(seed=seed)
        np.testing.assert_array_equal(obs, true_obs)
        act = balancing_actions(seed)
        y = np.zeros(1)  # the filter restarts at zero every episode
        for t in range(STEPS):
            u = act(true_obs)
            y = y + ALPHA * (u.astype(np.float64) - y)
            obs, reward, terminated, truncated, info = env.step(u)
            np.testing.assert_allclose(info["applied_action"], y, rtol=1e-5, atol=1e-6)
            if t == 0:
                np.testing.assert_allclose(info["applied_action"], ALPHA * u, rtol=1e-6)
            true_obs, true_reward, true_term, _, _ = twin.step(info["applied_action"])
            # The inner env got the filtered action, not the command.
            np.testing.assert_array_equal(obs, true_obs)
            assert reward == true_reward and terminated == true_term
            assert not terminated, f"episode {episode} ended at step {t}; the test needs {STEPS} steps"


def test_action_delay_actually_lags_the_command():
    env = LowPassDelay(plain_env(), TAU, on="action")
    env.reset(seed=0)
    applied = [env.step(np.array([1.0], dtype=np.float32))[4]["applied_action"][0] for _ in range(5)]
    # A step command of 1 is approached as 1 - (1 - alpha)^k, strictly increasing, never reached.
    np.testing.assert_allclose(applied, [1 - (1 - ALPHA) ** k for k in range(1, 6)], rtol=1e-6)
    assert all(a < b for a, b in zip(applied, applied[1:])) and applied[-1] < 1.0


# ---- perception delay ----------------------------------------------------------

@pytest.mark.parametrize("on", ["observation", "both"])
def test_observation_delay_follows_low_pass_recursion(on):
    env = LowPassDelay(plain_env(), TAU, on=on)
    twin = plain_env()  # the true state, driven by the same applied actions
    for seed in [5, 6]:  # the second episode checks that the filter restarts
        obs, _ = env.reset(seed=seed)
        true_obs, _ = twin.reset(seed=seed)
        z = true_obs.astype(np.float64).copy()  # starts at the first observation after reset
        np.testing.assert_array_equal(obs, z)
        act = balancing_actions(seed)
        y = np.zeros(1)
        for t in range(STEPS):
            u = act(true_obs)
            obs, _, terminated, _, info = env.step(u)
            if on == "both":
                y = y + ALPHA * (u.astype(np.float64) - y)
                np.testing.assert_allclose(info["applied_action"], y, rtol=1e-5, atol=1e-6)
            else:
                np.testing.assert_array_equal(info["applied_action"], u)
            true_obs, _, true_term, _, _ = twin.step(info["applied_action"])
            z = z + ALPHA * (true_obs - z)
            np.testing.assert_allclose(obs, z, rtol=1e-9, atol=1e-12)
            assert obs.shape == env.observation_space.shape and obs.dtype == true_obs.dtype
            assert terminated == true_term
            assert not terminated, f"episode ended at step {t}; the test needs {STEPS} steps"
        # A delayed observation really differs from the true one once the pole moves.
        assert not np.allclose(obs, true_obs)


def test_observation_delay_returns_copies():
    env = LowPassDelay(plain_env(), TAU, on="observation")
    obs, _ = env.reset(seed=0)
    obs[:] = 123.0  # a caller scribbling on its observation must not corrupt the filter
    obs2, *_ = env.step(np.zeros(1, dtype=np.float32))
    assert np.all(np.abs(obs2) < 1.0)


# ---- observation history -------------------------------------------------------

@pytest.mark.parametrize("k", [2, 4])
def test_history_stacks_frames_newest_last(k):
    env = make_env(EnvConfig(history=k))
    twin = plain_env()
    assert env.observation_space.shape == (k * 4,)
    obs, _ = env.reset(seed=1)
    first, _ = twin.reset(seed=1)
    assert obs.shape == (k * 4,)
    np.testing.assert_array_equal(obs, np.tile(first, k))  # reset pads with the first observation
    frames = [first] * k
    rng = np.random.default_rng(1)
    for _ in range(k + 2):
        u = rng.uniform(-0.2, 0.2, size=1).astype(np.float32)
        prev = obs
        obs, _, terminated, _, _ = env.step(u)
        true_obs, *_ = twin.step(u)
        frames = frames[1:] + [true_obs]
        np.testing.assert_array_equal(obs[-4:], true_obs)  # newest frame is the last block
        np.testing.assert_array_equal(obs[:-4], prev[4:])  # the others shifted by one frame
        np.testing.assert_array_equal(obs, np.concatenate(frames))
        assert not terminated
    obs, _ = env.reset(seed=2)
    first, _ = twin.reset(seed=2)
    np.testing.assert_array_equal(obs, np.tile(first, k))  # the old episode is gone


# ---- Gymnasium's env checker -----------------------------------------------------

@pytest.mark.parametrize(
    "settings",
    [
        dict(delay=0.2, delay_on="action"),
        dict(delay=0.2, delay_on="observation"),
        dict(delay=0.2, delay_on="both"),
        dict(history=3),
        dict(reward="quadratic"),
        dict(reward="alive", delay=0.2, delay_on="both", history=4),
    ],
    ids=["delay-action", "delay-observation", "delay-both", "history", "reward", "all-combined"],
)
def test_wrapped_env_passes_gymnasium_check_env(settings):
    env = make_env(EnvConfig(**settings))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    env.close()
    # The checker reports most problems (observation outside its space, wrong dtype,
    # non-deterministic reset) as warnings: only advice that also applies to the bare
    # InvertedPendulum, or that the env is wrapped (it is, on purpose), is acceptable.
    problems = [str(w.message) for w in caught if not any(ok in str(w.message) for ok in BENIGN_CHECKER_ADVICE)]
    assert problems == []


BENIGN_CHECKER_ADVICE = (
    "is different from the unwrapped version",
    "we recommend using a symmetric and normalized space",
    "minimum value is -infinity",
    "maximum value is infinity",
)


# ---- reward shaping --------------------------------------------------------------

# The documented value of each built-in, from (next_obs, action, task reward, terminated).
DOCUMENTED = {
    "task": lambda o, a, r, term: r,
    "alive": lambda o, a, r, term: 0.0 if term else 1.0,
    "quadratic": lambda o, a, r, term: r - 0.1 * float(np.sum(o**2)),
    "action-penalty": lambda o, a, r, term: r - 0.01 * float(np.sum(a**2)),
}


def test_builtin_rewards_are_the_documented_ones():
    assert set(BUILTIN) == set(DOCUMENTED)


@pytest.mark.parametrize("name", sorted(DOCUMENTED))
def test_builtin_reward_values(name):
    env = make_env(EnvConfig(reward=name))
    twin = plain_env()
    env.reset(seed=0)
    twin.reset(seed=0)
    action = np.array([2.5], dtype=np.float32)  # pushes the pole over within a few steps
    for _ in range(50):
        obs, reward, terminated, _, info = env.step(action)
        true_obs, true_reward, true_term, _, _ = twin.step(action)
        np.testing.assert_array_equal(obs, true_obs)
        assert info.get("task_reward", true_reward) == true_reward  # the task's own reward is kept
        assert reward == pytest.approx(DOCUMENTED[name](true_obs, action, true_reward, true_term), abs=1e-9)
        if terminated:
            break
    assert terminated, "the terminating step was not reached"


def test_shaped_env_keeps_task_reward_in_info():
    env = make_env(EnvConfig(reward="quadratic"))
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    assert info["task_reward"] == 1.0
    assert reward < info["task_reward"]  # quadratic subtracts a positive penalty


def test_unshaped_make_env_reports_task_reward():
    env = make_env(EnvConfig(reward="alive"), shaped=False)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    assert "task_reward" not in info


USER_REWARD = textwrap.dedent(
    """
    def double_plus_half(obs, action, reward, terminated, info):
        return 2.0 * reward + 0.5

    not_a_function = 3
    """
)


def _check_user_reward(spec: str) -> None:
    fn = resolve_reward(spec)
    assert fn(None, None, 1.0, False, {}) == 2.5
    env = make_env(EnvConfig(reward=spec))
    twin = plain_env()
    env.reset(seed=0)
    twin.reset(seed=0)
    for _ in range(5):
        _, reward, _, _, info = env.step(np.zeros(1, dtype=np.float32))
        _, true_reward, *_ = twin.step(np.zeros(1, dtype=np.float32))
        assert info["task_reward"] == true_reward
        assert reward == 2.0 * true_reward + 0.5


def test_user_reward_as_module_in_working_directory(tmp_path, monkeypatch):
    (tmp_path / "motorlab_test_cwd_reward.py").write_text(USER_REWARD)
    monkeypatch.chdir(tmp_path)
    _check_user_reward("motorlab_test_cwd_reward:double_plus_half")


def test_user_reward_as_module_on_sys_path(tmp_path, monkeypatch):
    pkg = tmp_path / "motorlab_test_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "shaping.py").write_text(USER_REWARD)
    monkeypatch.syspath_prepend(str(tmp_path))
    _check_user_reward("motorlab_test_pkg.shaping:double_plus_half")


def test_user_reward_as_file_path(tmp_path):
    path = tmp_path / "sub" / "my_reward.py"
    path.parent.mkdir()
    path.write_text(USER_REWARD)
    _check_user_reward(f"{path}:double_plus_half")


@pytest.mark.parametrize(
    "spec, fragment",
    [
        ("quadratik", "quadratic"),  # unknown built-in: suggests the close match
        ("motorlab_no_such_module_xyz:f", "motorlab_no_such_module_xyz"),
        ("{tmp}/missing.py:f", "missing.py"),
        ("{tmp}/rewards_ok.py:no_such_function", "no_such_function"),
        ("{tmp}/rewards_ok.py:not_a_function", "not_a_function"),
        ("{tmp}/rewards_broken.py:f", "rewards_broken"),
    ],
)
def test_bad_reward_specs_raise(tmp_path, spec, fragment):
    (tmp_path / "rewards_ok.py").write_text(USER_REWARD)
    (tmp_path / "rewards_broken.py").write_text("raise RuntimeError('boom')\n")
    spec = spec.format(tmp=tmp_path)
    with pytest.raises(MotorlabError, match=fragment):
        resolve_reward(spec)
    with pytest.raises(MotorlabError):
        make_env(EnvConfig(reward=spec))
