"""MyoSuite through motorlab: ids register on first use, the hand has the documented
sizes, misspelled ids get suggestions, and a missing MyoSuite says how to install it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import motorlab.envs.ids
from motorlab.envs import EnvConfig, check_env_id, make_env
from motorlab.errors import MotorlabError
from motorlab.evaluation import step_success
from motorlab.synergy_runs.activations import muscle_activations
from tests.helpers import HAND_ID, HAND_MUSCLES, assert_one_line_error, run_cli

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def test_hand_sizes_and_muscles():
    env = make_env(EnvConfig(id=HAND_ID))
    assert env.observation_space.shape == (200,)
    assert env.action_space.shape == (HAND_MUSCLES,)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (200,)
    env.action_space.seed(0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert obs.shape == (200,) and np.all(np.isfinite(obs)) and np.isfinite(reward)
    assert step_success(info) is not None  # MyoSuite reports info["solved"] every step
    act = muscle_activations(env)
    assert act.shape == (HAND_MUSCLES,) and act.min() >= 0.0 and act.max() <= 1.0
    env.close()


def test_misspelled_myosuite_id_suggests_the_right_one():
    with pytest.raises(MotorlabError, match="did you mean myoHandReorient8-v0"):
        check_env_id("myoHandReorent8-v0")


def test_cli_misspelled_myosuite_id(tmp_path):
    proc = run_cli("train", "myoHandReorent8-v0", "--no-progress", "--out", tmp_path / "out")
    assert_one_line_error(proc, "myoHandReorent8-v0", "myoHandReorient8-v0")
    assert not (tmp_path / "out").exists()


def test_unknown_myo_id_with_myosuite_installed_is_an_unknown_id():
    with pytest.raises(MotorlabError, match="unknown env id 'myoNotThere-v0'") as e:
        check_env_id("myoNotThere-v0")
    assert "pip install" not in str(e.value)


def test_missing_myosuite_says_how_to_install(monkeypatch):
    monkeypatch.setattr(motorlab.envs.ids, "register_myosuite", lambda: False)
    assert "myoNotThere-v0" not in gym.registry
    with pytest.raises(MotorlabError, match="pip install myosuite") as e:
        check_env_id("myoNotThere-v0")
    assert "myoNotThere-v0" in str(e.value) and "not installed" in str(e.value)
    with pytest.raises(MotorlabError, match="pip install myosuite"):
        make_env(EnvConfig(id="myoNotThere-v0"))


def test_cli_error_for_a_myosuite_env_is_one_line(tmp_path):
    """A user mistake on a MyoSuite env prints one line, like on any other env. Building a
    MyoSuite hand makes MuJoCo's C library print a warning of its own to stderr; motorlab
    must not let it through (mujoco.set_mju_user_warning can route it)."""
    proc = run_cli("train", HAND_ID, "--sar", tmp_path / "missing.npz", "--no-progress", "--out", tmp_path / "out")
    assert_one_line_error(proc, "missing.npz")
