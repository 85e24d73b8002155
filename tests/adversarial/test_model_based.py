"""What an adversarial user tried on the model-based and synergy commands (issue 35), as they would
type it: a Dict observation (now works), discrete actions, damaged data files, a reward that is NaN
outside the range its probes cover. Each mistake exits 2 with one line naming the problem and the fix,
no traceback, and leaves every earlier file as it was (helpers.snapshot before and after)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import textwrap

import numpy as np
import pytest

from motorlab.envs.spaces import encode_space
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_here, snapshot

with contextlib.redirect_stderr(io.StringIO()):  # its import prints a notice about other envs, once
    import gymnasium as gym
    import gymnasium_robotics  # noqa: F401  (registers PointMaze_UMaze-v3 in this process)

MAZE = "gymnasium_robotics:PointMaze_UMaze-v3"
NUMPY_PICKLE_ADVICE = ("allow_pickle", "pickle.load", "unsafely")


@pytest.fixture(scope="module")
def maze(tmp_path_factory):
    """Finished runs on the point maze, a Dict observation env: 4 random episodes, a model fit on them."""
    root = tmp_path_factory.mktemp("maze")
    assert_ok(run_here("dynamics", "collect", MAZE, "--episodes", "4", "--workers", "1", "--out", root / "data"))
    assert_ok(run_here("dynamics", "fit", root / "data", "--epochs", "3", "--out", root / "model"))
    return root


@pytest.fixture(scope="module")
def cartpole_run(tmp_path_factory):
    """A finished run folder of CartPole-v1 (Discrete(2) actions), as `motorlab train` leaves one: the
    refusals below come before its policy is read, so its settings and summary are all they see."""
    run = tmp_path_factory.mktemp("cartpole")
    (run / "config.toml").write_text('algo = "ppo"\n\n[env]\nid = "CartPole-v1"\n')
    (run / "summary.json").write_text('{"eval_return_mean": 9.4}')
    return run


# ---- a Dict observation: what gave tracebacks now works ----------------------------------------


def test_dynamics_collect_on_a_dict_observation_env(maze):
    s = read_summary(maze / "data")
    assert s["state_size"] == 8 and s["transitions"] == 4 * 300 and s["numerical_faults"] == 0
    with np.load(maze / "data" / "transitions.npz") as f:
        meta = json.loads(str(f["meta"]))
    assert [k["key"] for k in meta["obs_layout"]] == ["achieved_goal", "desired_goal", "observation"]
    assert [(k["start"], k["stop"]) for k in meta["obs_layout"]] == [(0, 2), (2, 4), (4, 8)]
    assert json.loads((maze / "model" / "model.json").read_text())["obs_layout"] == meta["obs_layout"]


def test_synergies_collect_on_a_dict_observation_env(tmp_path):
    assert_ok(run_here("train", MAZE, "--algo", "lqr", "--timesteps", "300", "--no-progress", "--out",
                       tmp_path / "lqr"))
    proc = run_here("synergies", "collect", tmp_path / "lqr", "--episodes", "2", "--preview", "2", "--percentile",
                    "0", "--workers", "1", "--out", tmp_path / "collect")
    assert_ok(proc)
    s = read_summary(tmp_path / "collect")
    assert s["signal"] == "ctrl" and s["n_signals"] == 2 and s["samples"] == 600 and s["numerical_faults"] == 0


# ---- discrete actions: refused in one line, before anything is written --------------------------


def discrete_transitions(maze, folder):
    """The maze's transitions relabelled as CartPole's, with its Discrete(2) action space in the meta
    (motorlab's collect refuses such an env, so a file of one is made by other hands)."""
    with np.load(maze / "data" / "transitions.npz") as f:
        arrays = dict(f)
    meta = json.loads(str(arrays["meta"]))
    meta.update(env_id="CartPole-v1", action_space=encode_space(gym.spaces.Discrete(2)))
    folder.mkdir()
    np.savez(folder / "transitions.npz", **dict(arrays, meta=np.array(json.dumps(meta))))
    return folder


@pytest.mark.parametrize("command, fragments", [
    (["dynamics", "collect", "CartPole-v1", "--episodes", "2"],
     ["dynamics collect needs continuous (Box) actions", "CartPole-v1's actions are Discrete(2)",
      "motorlab train CartPole-v1 --algo ppo"]),
    (["mpc", "CartPole-v1", "--model", "{model}"], ["MPC needs continuous (Box) actions",
                                                    "CartPole-v1's actions are Discrete(2)"]),
    (["mbrl", "CartPole-v1", "--rounds", "1"], ["mbrl (MPC on a learned model) needs continuous (Box) actions",
                                                "Discrete(2)"]),
    (["synergies", "collect", "{cartpole}"], ["synergies collect needs continuous (Box) actions", "Discrete(2)"]),
    (["dynamics", "fit", "{discrete}"], ["dynamics fit", "needs continuous (Box) actions", "Discrete(2)",
                                         "motorlab train CartPole-v1 --algo ppo"]),
], ids=["dynamics-collect", "mpc", "mbrl", "synergies-collect", "dynamics-fit"])
def test_discrete_actions_are_one_line_before_any_work(maze, cartpole_run, tmp_path, command, fragments):
    paths = {"model": maze / "model", "cartpole": cartpole_run,
             "discrete": discrete_transitions(maze, tmp_path / "discrete") if "{discrete}" in command else None}
    args = [a.format(**paths) if a.startswith("{") else a for a in command]
    before = snapshot(maze, cartpole_run)
    assert_one_line_error(run_here(*args, "--out", tmp_path / "out"), *fragments)
    assert not (tmp_path / "out").exists()
    # into a finished run's folder: refused before the folder is touched
    assert_one_line_error(run_here(*args, "--out", maze / "data"), *fragments)
    assert snapshot(maze, cartpole_run) == before


def test_the_lqr_learner_refuses_discrete_actions(tmp_path):
    assert_one_line_error(run_here("train", "CartPole-v1", "--algo", "lqr", "--timesteps", "100", "--no-progress",
                                   "--out", tmp_path / "out"), "Discrete(2)")


# ---- damaged data files: one line naming the file and the fix, never numpy's pickle advice ---------


def _random_bytes(good: bytes) -> bytes:
    return np.random.default_rng(0).bytes(4096)


def _truncated(good: bytes) -> bytes:
    return good[:len(good) // 2]


def _object_array(good: bytes) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, states=np.array([{"a": 1}], dtype=object))
    return buf.getvalue()


def _npy(good: bytes) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.zeros((4, 3)))
    return buf.getvalue()


DAMAGE = [(_random_bytes, "it is not an .npz archive"), (_truncated, "the archive is damaged or cut short"),
          (_object_array, "it holds arrays of Python objects, which motorlab never unpickles"),
          (_npy, "it is not an .npz archive")]


@pytest.mark.parametrize("damage, reason", DAMAGE, ids=[d.__name__.strip("_") for d, _ in DAMAGE])
def test_a_damaged_transitions_file_is_one_line(maze, tmp_path, damage, reason):
    bad = tmp_path / "copy"
    bad.mkdir()
    (bad / "transitions.npz").write_bytes(damage((maze / "data" / "transitions.npz").read_bytes()))
    before = snapshot(maze)
    for out in (tmp_path / "out", maze / "model"):  # a new folder, and a finished fit's
        message = assert_one_line_error(run_here("dynamics", "fit", bad, "--out", out),
                                        f"{bad / 'transitions.npz'} is not a transitions file written by "
                                        f"`motorlab dynamics collect` ({reason}", "re-run `motorlab dynamics collect`")
        assert not any(advice in message for advice in NUMPY_PICKLE_ADVICE), message
    assert not (tmp_path / "out").exists() and snapshot(maze) == before


@pytest.mark.parametrize("command", ["vaf", "fit"])
def test_a_random_bytes_activations_file_is_one_line(tmp_path, command):
    bad = tmp_path / "activations.npz"
    bad.write_bytes(_random_bytes(b""))
    before = snapshot(bad)
    message = assert_one_line_error(run_here("synergies", command, bad, *(["--vaf", "0.8"] if command == "fit" else []),
                                             "--out", tmp_path / "out"), str(bad), "not an .npz archive",
                                    "collect it again")
    assert not any(advice in message for advice in NUMPY_PICKLE_ADVICE), message
    assert not (tmp_path / "out").exists() and snapshot(bad) == before


def test_a_damaged_model_is_one_line_for_mpc_and_check(maze, tmp_path):
    before = snapshot(maze)
    noisy = tmp_path / "noisy"
    shutil.copytree(maze / "model", noisy)
    (noisy / "model.safetensors").write_bytes(_random_bytes(b""))
    for command in (["mpc", MAZE, "--model", noisy], ["dynamics", "check", noisy]):
        assert_one_line_error(run_here(*command, "--out", tmp_path / "out"), "model.safetensors is damaged",
                              "re-run `motorlab dynamics fit`")
    # a model.json whose key slices were edited: read, and refused by the env it does not fit
    moved = tmp_path / "moved"
    shutil.copytree(maze / "model", moved)
    model_json = json.loads((moved / "model.json").read_text())
    model_json["obs_layout"] = [dict(k, key=k["key"].upper()) for k in model_json["obs_layout"]]
    (moved / "model.json").write_text(json.dumps(model_json))
    assert_one_line_error(run_here("mpc", MAZE, "--model", moved, "--out", tmp_path / "out"),
                          "ACHIEVED_GOAL 0:2", "achieved_goal 0:2", "refit the model")
    model_json["obs_layout"] = "achieved_goal 0:2"
    (moved / "model.json").write_text(json.dumps(model_json))
    assert_one_line_error(run_here("mpc", MAZE, "--model", moved, "--out", tmp_path / "out"),
                          "obs_layout should be", "re-run `motorlab dynamics fit`")
    assert not (tmp_path / "out").exists() and snapshot(maze) == before


# ---- a reward that is NaN outside the probes' range -------------------------------------------------


def test_a_nan_reward_is_rejected_counted_and_warned_about_once(maze, tmp_path, monkeypatch):
    (tmp_path / "nan_outside.py").write_text(textwrap.dedent('''
        import torch


        def reward(obs, action, next_obs):  # finite on the probes, in [-0.5, 0.5]; NaN beyond |x| = 0.6
            r = -torch.linalg.vector_norm(next_obs[..., 0:2] - next_obs[..., 2:4], dim=-1)
            return torch.where(next_obs[..., 0].abs() < 0.6, r, torch.nan)
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("MOTORLAB_IMPORTS", os.environ.get("MOTORLAB_IMPORTS", ""))
    out = tmp_path / "mpc"
    proc = run_here("mpc", MAZE, "--model", maze / "model", "--episodes", "1", "--horizon", "5", "--population", "30",
                    "--iterations", "2", "--elites", "4", "--reward", "nan_outside:reward", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["planner_faults"] > 0 and s["planner_nonfinite_rewards"] > 0 and s["episode_faults"] == 0
    assert s["numerical_faults"] == s["planner_faults"]  # was 0: the report
    planner_warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning: planner:")]
    assert len(planner_warnings) == 1 and "reward nan_outside:reward" in planner_warnings[0], proc.stderr
    assert "Traceback" not in proc.stderr
