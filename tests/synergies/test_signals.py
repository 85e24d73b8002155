"""Synergies beyond muscles: `collect --signal auto|act|ctrl|action` records muscle activations
(MyoSuite), the actuator controls MuJoCo applied (a Gymnasium robot) or the env's actions (an env
without MuJoCo); a SAR of motor commands drives the env's actions inside its bounds; the robot
recipe `sar-ant-quick` runs end to end (at the tests' scale)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.kinds.synergies import COLLECT, FIT
from motorlab.synergies import SynergyActionWrapper, fit_sar, save_sar
from motorlab.synergies.sar import load_sar, signal_of
from motorlab.synergy_runs.activations import load_activations, read_signal, resolve_signal, signal_bounds
from tests.helpers import (
    ENV_ID,
    HAND_ID,
    HAND_MUSCLES,
    TINY_PPO,
    assert_ok,
    assert_one_line_error,
    read_summary,
    run_cli,
    run_here,
    run_kind,
    scaled_recipe,
)

ANT = "Ant-v5"  # 8 motors, ctrlrange [-1, 1]
HUMANOID = "Humanoid-v5"  # 17 motors, ctrlrange [-0.4, 0.4]
PENDULUM = "Pendulum-v1"  # no MuJoCo: torque in [-2, 2]


def load(path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def motor_sar(env_id: str, n: int = 3, seed: int = 0, signal: str = "ctrl"):
    """A SAR fitted to synthetic commands of `env_id`'s actuators: n sources mixed, inside the bounds."""
    env = make_env(EnvConfig(id=env_id))
    low, high = env.action_space.low.astype(float), env.action_space.high.astype(float)
    env.close()
    rng = np.random.default_rng(seed)
    mixed = np.tanh(rng.normal(size=(500, n)) @ rng.normal(size=(n, low.size)))  # in (-1, 1)
    x = low + (mixed + 1) / 2 * (high - low)
    return fit_sar(x, n_synergies=n, method="pca-ica", seed=seed, source_env=env_id, signal=signal,
                   bounds=(low, high))


# ---- which signal: auto picks act, else ctrl, else action --------------------------------------

@pytest.mark.parametrize("env_id, expected", [(HAND_ID, "act"), (ANT, "ctrl"), (ENV_ID, "ctrl"),
                                              (PENDULUM, "action")])
def test_auto_picks_act_then_ctrl_then_action(env_id, expected):
    env = make_env(EnvConfig(id=env_id))
    assert resolve_signal(env, "auto") == expected
    assert resolve_signal(env, expected) == expected
    env.close()


def test_muscles_are_act_in_zero_one():
    env = make_env(EnvConfig(id=HAND_ID))
    env.reset(seed=0)
    action = env.action_space.sample()
    env.step(action)
    low, high = signal_bounds(env, "act")
    np.testing.assert_array_equal(low, np.zeros(HAND_MUSCLES))
    np.testing.assert_array_equal(high, np.ones(HAND_MUSCLES))
    # unchanged: data.act itself, not the action
    np.testing.assert_array_equal(read_signal(env, "act", action, (low, high)),
                                  np.asarray(env.unwrapped.data.act, dtype=np.float32))
    env.close()


def test_ctrl_is_what_the_actuators_got():
    env = make_env(EnvConfig(id=ANT))
    model = env.unwrapped.model
    low, high = signal_bounds(env, "ctrl")
    np.testing.assert_array_equal(low, model.actuator_ctrlrange[:, 0])
    np.testing.assert_array_equal(high, model.actuator_ctrlrange[:, 1])
    env.reset(seed=0)
    action = np.linspace(-3, 3, model.nu).astype(np.float32)  # partly outside the ctrlrange
    env.unwrapped.step(action)  # the raw env: MuJoCo clamps what it applies, data.ctrl keeps the request
    np.testing.assert_array_equal(env.unwrapped.data.ctrl, action)
    np.testing.assert_array_equal(read_signal(env, "ctrl", action, (low, high)), np.clip(action, -1, 1))
    env.close()


def test_action_of_an_env_without_mujoco():
    env = make_env(EnvConfig(id=PENDULUM))
    low, high = signal_bounds(env, "action")
    np.testing.assert_array_equal(low, [-2.0]) and np.testing.assert_array_equal(high, [2.0])
    np.testing.assert_array_equal(read_signal(env, "action", np.array([5.0]), (low, high)), [2.0])
    env.close()


@pytest.mark.parametrize("env_id, signal, fragment", [(PENDULUM, "act", "--signal"), (PENDULUM, "ctrl", "--signal action"),
                                                      (ANT, "act", "--signal ctrl"), (ANT, "muscles", "auto, act")])
def test_a_signal_the_env_lacks_is_a_clear_error(env_id, signal, fragment):
    env = make_env(EnvConfig(id=env_id))
    with pytest.raises(MotorlabError, match=fragment):
        resolve_signal(env, signal)
    env.close()


# ---- collect: activations.npz says what it holds --------------------------------------------

@pytest.fixture(scope="module")
def pendulum_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "pendulum"
    assert_ok(run_cli("train", PENDULUM, *TINY_PPO, "--seed", "0", "--no-progress", "--out", out))
    return out


def test_collect_action_on_pendulum_by_cli(pendulum_run, tmp_path):
    out = tmp_path / "collect"
    assert_ok(run_cli("synergies", "collect", pendulum_run, "--episodes", "2", "--preview", "2", "--percentile", "0",
                      "--workers", "1", "--out", out))  # --signal auto
    d = load(out / "activations.npz")
    assert str(d["signal"]) == "action" and json.loads(str(d["metadata"]))["signal"] == "action"
    np.testing.assert_array_equal(d["low"], [-2.0]) and np.testing.assert_array_equal(d["high"], [2.0])
    acts = d["activations"]
    assert acts.shape == (400, 1) and acts.min() >= -2 and acts.max() <= 2 and acts.std() > 0
    s = read_summary(out)
    assert s["signal"] == "action" and s["n_signals"] == s["n_muscles"] == 1


def test_cli_ctrl_on_pendulum_is_one_line(pendulum_run, tmp_path):
    proc = run_here("synergies", "collect", pendulum_run, "--signal", "ctrl", "--episodes", "2", "--preview", "2",
                    "--out", tmp_path / "out")
    assert_one_line_error(proc, PENDULUM, "--signal action")
    assert not (tmp_path / "out").exists()


def test_collect_ctrl_on_inverted_pendulum(ppo_run, tmp_path):
    s = run_kind(COLLECT, tmp_path / "collect", run=str(ppo_run), episodes=2, preview=2, percentile=0.0, workers=1)
    assert s["signal"] == "ctrl" and s["n_muscles"] == 1
    acts, meta = load_activations(tmp_path / "collect")
    assert meta["signal"] == "ctrl" and meta["env_id"] == ENV_ID
    np.testing.assert_array_equal(meta["low"], [-3.0]) and np.testing.assert_array_equal(meta["high"], [3.0])
    assert acts.min() >= -3 and acts.max() <= 3


def test_activations_written_before_signals_load_as_muscles(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "activations.npz"
    np.savez(path, activations=rng.uniform(0, 1, (50, 4)), episode=np.zeros(50, int),
             metadata=np.array(json.dumps({"env_id": HAND_ID})))  # the old layout: no signal, low, high
    acts, meta = load_activations(path)
    assert acts.shape == (50, 4) and meta["signal"] == "act" and meta["env_id"] == HAND_ID
    np.testing.assert_array_equal(meta["low"], np.zeros(4)) and np.testing.assert_array_equal(meta["high"], np.ones(4))
    s = run_kind(FIT, tmp_path / "fit", activations=str(path), n_synergies=2)
    assert s["signal"] == "act" and signal_of(load_sar(tmp_path / "fit" / "sar.npz"))[0] == "act"


# ---- a SAR of motor commands drives the env's actions, inside its bounds ------------------------

@pytest.mark.parametrize("env_id", [ANT, HUMANOID])
@pytest.mark.parametrize("phi", [1.0, 0.5])
def test_decoded_commands_stay_in_the_action_bounds(env_id, phi, tmp_path):
    sar = motor_sar(env_id)
    save_sar(sar, tmp_path / "sar.npz")
    assert signal_of(load_sar(tmp_path / "sar.npz"))[0] == "ctrl"
    env = make_env(EnvConfig(id=env_id, sar=str(tmp_path / "sar.npz"), phi=phi))
    wrapper = env
    while not isinstance(wrapper, SynergyActionWrapper):
        wrapper = wrapper.env
    inner = wrapper.env.action_space
    z = np.random.default_rng(1).uniform(-3, 3, (500, env.action_space.shape[0]))  # far past the synergy box too
    commands = np.array([wrapper.action(a) for a in z])
    assert commands.dtype == inner.dtype
    assert np.all(commands >= inner.low) and np.all(commands <= inner.high)
    assert np.mean((commands == inner.low) | (commands == inner.high)) < 0.9  # clipped, not pinned
    inside = np.random.default_rng(2).uniform(-1, 1, (50, sar.n_synergies))
    if phi == 1.0:  # where decode stays in range, the command is decode(z) itself
        d = sar.decode(inside)
        ok = np.all((d >= inner.low) & (d <= inner.high), axis=1)
        np.testing.assert_allclose(np.array([wrapper.action(a) for a in inside[ok]]), d[ok], atol=1e-5)
    env.close()


def test_recorded_bounds_map_onto_other_action_bounds():
    """A SAR of controls in [-0.4, 0.4] on an env whose actions are [-2, 2] (same size): decoded
    commands are rescaled from the one box to the other, then clipped."""
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.4, 0.4, (300, 1))
    sar = fit_sar(x, n_synergies=1, method="pca", signal="ctrl", bounds=([-0.4], [0.4]))
    env = SynergyActionWrapper(make_env(EnvConfig(id=PENDULUM)), sar)
    z = np.array([[-1.0], [0.0], [0.5], [1.0]])
    np.testing.assert_allclose([env.action(v)[0] for v in z], np.clip(sar.decode(z)[:, 0] * 5, -2, 2), atol=1e-5)


@pytest.mark.parametrize("phi", [1.0, 0.66])
def test_wrapped_robot_passes_check_env(phi):
    env = SynergyActionWrapper(make_env(EnvConfig(id=ANT)), motor_sar(ANT), phi=phi)
    check_env(env, skip_render_check=True)
    env.close()


def test_a_robot_sar_on_another_body_is_one_line(tmp_path):
    save_sar(motor_sar(ANT), tmp_path / "sar.npz")
    proc = run_here("train", HUMANOID, "--sar", tmp_path / "sar.npz", "--timesteps", "100", "--no-progress",
                    "--out", tmp_path / "out")
    assert_one_line_error(proc, "8 actuator controls", "(17,)")
    assert not (tmp_path / "out" / "summary.json").exists()


def test_a_non_box_action_space_is_a_clear_error():
    env = gym.make("CartPole-v1")
    with pytest.raises(MotorlabError, match="Discrete action space"):
        SynergyActionWrapper(env, motor_sar(ANT))


# ---- the robot recipe, end to end ---------------------------------------------------------

def test_robot_quick_recipe_end_to_end(tmp_path):
    out = tmp_path / "study"  # its training budgets divided by 4 (helpers.SCALED)
    assert_ok(run_cli("run", scaled_recipe("sar-ant-quick", tmp_path), "--out", out, timeout=600))
    summary = read_summary(out)
    for arm in ("sar-rl", "rl-e2e", "zeroshot-sar-rl", "zeroshot-rl-e2e"):
        assert np.isfinite(summary[f"{arm}.return_mean"]), arm
    assert summary["collect.signal"] == "ctrl" and summary["fit.signal"] == "ctrl"
    d = load(out / "collect" / "activations.npz")
    assert str(d["signal"]) == "ctrl" and d["activations"].shape[1] == 8
    np.testing.assert_array_equal(d["low"], -np.ones(8)) and np.testing.assert_array_equal(d["high"], np.ones(8))
    assert 1 <= summary["fit.n_synergies"] <= 8
    sar_rl = json.loads((out / "sar-rl" / "seed0" / "summary.json").read_text())
    assert sar_rl["env_id"] == ANT
