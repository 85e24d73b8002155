"""Disturbance wrappers: noise, latency, randomized ranges, pushes, MyoSuite's motor noise and
fatigue: their math, their restart with each episode, their seeding, Gymnasium's env checker,
and the one-line errors for bad settings."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from motorlab.envs import EnvConfig, make_env
from motorlab.envs.disturbances import GaussianNoise, Latency, RandomPush, mujoco_model_data, parse_span
from motorlab.envs.wrappers import LowPassDelay
from motorlab.errors import MotorlabError
from tests.helpers import assert_one_line_error, run_here

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

ENV_ID = "InvertedPendulum-v5"
DT = 0.04


def plain() -> gym.Env:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return gym.make(ENV_ID)


def actions(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-0.5, 0.5, size=1).astype(np.float32) for _ in range(n)]


# ---- amounts ----------------------------------------------------------------------------------

def test_amounts_are_numbers_or_ranges():
    assert parse_span(0.2, "x") == (0.2, 0.2)
    assert parse_span("0.05..0.3", "x") == (0.05, 0.3)
    assert parse_span([1, 3], "x", integer=True) == (1, 3)
    cfg = EnvConfig(delay="0.05..0.3", latency="0..3", obs_noise=[0.01, 0, 0.02, 0], push_force=[5, 20])
    assert (cfg.delay, cfg.latency, cfg.push_force) == ("0.05..0.3", "0..3", "5..20")  # TOML-friendly text
    assert EnvConfig(delay="0.2", latency="2").delay == 0.2 and EnvConfig(latency="2").latency == 2


@pytest.mark.parametrize("field, value, fragment", [
    ("delay", "0.3..0.05", "runs backwards"),
    ("obs_noise", "-0.1", "zero or more"),
    ("latency", "0.5..2", "whole numbers"),
    ("action_noise", "lots", "neither a number nor a range"),
    ("push_force", "nan", "zero or more"),
])
def test_bad_amounts_name_the_problem(field, value, fragment):
    with pytest.raises(MotorlabError, match=fragment):
        EnvConfig(**{field: value})


# ---- noise ------------------------------------------------------------------------------------

def test_observation_noise_is_gaussian_with_the_given_std_and_leaves_the_state_alone():
    env = GaussianNoise(plain(), obs_std=[0.0, 0.1, 0.0, 0.2])
    twin = plain()
    diffs = []
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        true, _ = twin.reset(seed=seed)
        diffs.append(obs - true)
        for a in actions(30, seed):
            obs, _, term, _, info = env.step(a)
            true, _, true_term, _, _ = twin.step(a)  # the noise never reaches the simulation
            assert term == true_term
            diffs.append(obs - true)
            if term:
                break
    d = np.array(diffs)
    assert np.all(d[:, [0, 2]] == 0)  # zero std: exact
    np.testing.assert_allclose(d[:, [1, 3]].std(axis=0), [0.1, 0.2], rtol=0.25)
    assert abs(d[:, 3].mean()) < 0.06  # zero mean


def test_action_noise_reaches_the_env_clipped_to_the_action_space():
    env = GaussianNoise(plain(), action_std=5.0)
    env.reset(seed=0)
    applied = np.array([env.step(np.zeros(1, np.float32))[4]["applied_action"] for _ in range(20)])
    assert np.all(np.abs(applied) <= 3.0) and np.any(np.abs(applied) == 3.0)  # InvertedPendulum's bounds
    assert len(np.unique(applied)) > 5


def test_per_element_std_must_match_the_size():
    with pytest.raises(MotorlabError, match="3 values but there are 4 elements"):
        make_env(EnvConfig(obs_noise=[0.1, 0.1, 0.1]))


# ---- latency ----------------------------------------------------------------------------------

@pytest.mark.parametrize("k", [1, 3])
def test_action_latency_applies_the_command_from_k_steps_ago(k):
    env = Latency(plain(), k, on="action")
    twin = plain()
    for seed in (0, 1):  # the second episode checks the restart: the rest action again first
        obs, _ = env.reset(seed=seed)
        true, _ = twin.reset(seed=seed)
        np.testing.assert_array_equal(obs, true)
        sent = actions(12, seed)
        for t, a in enumerate(sent):
            obs, _, _, _, info = env.step(a)
            expected = np.zeros(1) if t < k else sent[t - k]
            np.testing.assert_array_equal(info["applied_action"], expected)
            true, *_ = twin.step(np.asarray(expected, dtype=np.float32))
            np.testing.assert_array_equal(obs, true)


def test_observation_latency_shows_the_observation_from_k_steps_ago():
    env = Latency(plain(), 2, on="observation")
    twin = plain()
    first, _ = env.reset(seed=4)
    trues = [twin.reset(seed=4)[0]]
    for t, a in enumerate(actions(8)):
        obs, *_ = env.step(a)
        trues.append(twin.step(a)[0])
        np.testing.assert_array_equal(obs, first if t < 2 else trues[t + 1 - 2])


# ---- randomization ----------------------------------------------------------------------------

def test_randomized_ranges_repeat_per_seed_and_differ_per_episode():
    cfg = EnvConfig(id=ENV_ID, delay="0.05..0.3", latency="0..3", obs_noise="0..0.02", action_noise="0..0.1")
    env, again = make_env(cfg), make_env(cfg)
    drawn = [env.reset(seed=s)[1]["disturbances"] for s in (7, 8)]
    assert drawn[0] == again.reset(seed=7)[1]["disturbances"]  # reproducible per seed
    assert drawn[0] != drawn[1]
    unseeded = [env.reset()[1]["disturbances"] for _ in range(5)]  # training: the stream goes on
    assert len({tuple(d.values()) for d in unseeded}) == 5
    for d in drawn + unseeded:
        assert 0.05 <= d["delay"] <= 0.3 and d["latency"] in (0, 1, 2, 3) and 0 <= d["obs_noise"] <= 0.02
    # the same seed gives the same episode, step for step
    a, b = make_env(cfg), make_env(cfg)
    np.testing.assert_array_equal(a.reset(seed=3)[0], b.reset(seed=3)[0])
    for u in actions(10):
        np.testing.assert_array_equal(a.step(u)[0], b.step(u)[0])


def test_a_drawn_delay_sets_the_filter_of_that_episode():
    env = LowPassDelay(plain(), "0.05..0.3", on="action")
    _, info = env.reset(seed=1)
    tau = info["disturbances"]["delay"]
    assert env.alpha == pytest.approx(DT / tau)
    applied = env.step(np.ones(1, np.float32))[4]["applied_action"]
    assert applied[0] == pytest.approx(DT / tau, rel=1e-5)


def test_noise_leaves_the_envs_own_initial_states_alone():
    noisy = make_env(EnvConfig(id=ENV_ID, obs_noise=0.0, action_noise=0.1))
    plain_obs = plain().reset(seed=5)[0]
    noisy.reset(seed=5)
    np.testing.assert_array_equal(noisy.unwrapped.data.qpos, plain_obs[:2])  # same start as without noise


def test_every_disturbance_passes_gymnasiums_env_checker():
    cfg = EnvConfig(id=ENV_ID, delay="0.05..0.3", latency="1..2", obs_noise=0.01, action_noise="0..0.1",
                    push_body="pole", push_force="1..2", push_interval=0.2, history=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(make_env(cfg), skip_render_check=True)


# ---- pushes -----------------------------------------------------------------------------------

def test_a_push_moves_the_body():
    pushed = RandomPush(plain(), "cart", force=50.0, interval=0.12, direction="x", duration=0.08)
    still = plain()
    pushed.reset(seed=0)
    still.reset(seed=0)
    forces = []
    for _ in range(6):
        _, _, _, _, info = pushed.step(np.zeros(1, np.float32))
        still.step(np.zeros(1, np.float32))
        forces.append(info["push_force"])
    forces = np.array(forces)
    pushing = np.flatnonzero(np.abs(forces[:, 0]) > 0)
    assert list(pushing) == [3, 4]  # starts after 0.12 s (3 steps) and lasts 0.08 s (2 steps)
    assert np.all(np.abs(forces[pushing, 0]) == 50.0) and np.all(forces[:, 1:] == 0)
    cart_moved = pushed.unwrapped.data.qpos[0] - still.unwrapped.data.qpos[0]
    assert abs(cart_moved) > 0.01 and np.sign(cart_moved) == np.sign(forces[pushing[0], 0])
    assert np.all(pushed.unwrapped.data.xfrc_applied == 0)  # cleared once the push ended


def test_a_push_to_an_unknown_body_lists_the_bodies():
    with pytest.raises(MotorlabError, match="did you mean pole.*cart, pole"):
        make_env(EnvConfig(id=ENV_ID, push_body="poles"))


def test_cli_bad_range_is_one_line(tmp_path):
    proc = run_here("evaluate", "pid", "--env", ENV_ID, "--obs-noise", "0.05..0.01", "--out", tmp_path / "e")
    assert_one_line_error(proc, "observation noise", "runs backwards")
    assert not (tmp_path / "e").exists()


# ---- MyoSuite's own wrappers ------------------------------------------------------------------

MYO = "myoElbowPose1D6MRandom-v0"


def test_motor_noise_and_fatigue_go_through_myosuite():
    from myosuite.envs.wrappers import FatigueWrapper, MotorNoiseWrapper

    env = make_env(EnvConfig(id=MYO, motor_noise=1.0, fatigue="fresh"))
    layers = []
    e = env
    while isinstance(e, gym.Wrapper):
        layers.append(type(e))
        e = e.env
    assert MotorNoiseWrapper in layers and FatigueWrapper in layers
    quiet = make_env(EnvConfig(id=MYO))
    u = np.full(env.action_space.shape, 0.5, np.float32)
    env.reset(seed=0)
    quiet.reset(seed=0)
    env.step(u)
    quiet.step(u)
    # the noise reaches the muscles: the excitations MuJoCo got differ from the noiseless env's
    assert not np.allclose(mujoco_model_data(env)[1].ctrl, mujoco_model_data(quiet)[1].ctrl)


def test_motor_noise_needs_muscles():
    with pytest.raises(MotorlabError, match="MyoSuite's muscles.*--action-noise"):
        make_env(EnvConfig(id=ENV_ID, motor_noise=1.0))
