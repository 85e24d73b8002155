"""A user's own body and task (tests/userpkg: a three-joint MuJoCo arm Gymnasium does not have,
registered by its own module) through every workflow: Gymnasium's `module:EnvId` form,
`--import MODULE`, a recipe's `imports`, sweeps on a pool and on Ray, run folders that rebuild
the env in a fresh process, and one-line errors for modules that go wrong."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from tests.helpers import (
    TINY_PPO,
    USER_PACKAGES,
    assert_ok,
    assert_one_line_error,
    read_summary,
    run_cli,
    user_packages_importable,
)

USER_PATH = USER_PACKAGES  # where the user's package lives (they would pip install -e it)
ARM = "userpkg.arm:ArmReach-v0"


@pytest.fixture(scope="module", autouse=True)
def user_package_on_path():
    """The package is importable as installed packages are, in every process motorlab starts."""
    os.environ.pop("MOTORLAB_IMPORTS", None)
    with user_packages_importable():
        yield


@pytest.fixture(scope="module")
def arm_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("arm") / "ppo"
    assert_ok(run_cli("train", ARM, *TINY_PPO, "--out", out, "--no-progress"))
    return out


def test_module_env_id_trains_and_the_folder_rebuilds_its_env(arm_run, tmp_path):
    summary = read_summary(arm_run)
    assert summary["env_id"] == ARM and summary["timesteps"] == 256
    # a fresh process, given only the folder: the id says which module registers the env
    proc = run_cli("evaluate", arm_run, "--episodes", "3", "--out", tmp_path / "eval")
    assert_ok(proc)
    evaluation = read_summary(tmp_path / "eval")
    assert evaluation["env_id"] == ARM and evaluation["episodes"] == 3
    assert evaluation["episode_length_mean"] == 100  # the registered time limit
    assert_ok(run_cli("video", arm_run, "--episodes", "1", "--width", "64", "--height", "48",
                      "--out", tmp_path / "video"))
    assert (tmp_path / "video" / "episode_0.mp4").stat().st_size > 1000


def test_import_flag_and_folders_that_remember_it(tmp_path):
    # a folder trained with --import remembers it: test_synergies_of_the_arms_motor_commands_and_sar_training
    assert_ok(run_cli("--import", "userpkg.arm", "evaluate", "zero", "--env", "ArmReach-v0", "--episodes", "1",
                      "--out", tmp_path / "zero"))
    assert_ok(run_cli("dynamics", "collect", "ArmReach-v0", "--import=userpkg.arm", "--episodes", "8",
                      "--workers", "2", "--out", tmp_path / "transitions"))  # workers: fresh processes
    assert read_summary(tmp_path / "transitions")["transitions"] == 8 * 100


def test_synergies_of_the_arms_motor_commands_and_sar_training(arm_run, tmp_path):
    """Collect (from the folder, fresh processes), fit and train in the synergy space of a body
    without muscles: the signal is the actuator commands. The env of that training is named by
    --import, and later commands on its folder import the module again without being told."""
    assert_ok(run_cli("synergies", "collect", arm_run, "--episodes", "6", "--preview", "4", "--workers", "2",
                      "--out", tmp_path / "commands"))
    collected = read_summary(tmp_path / "commands")
    assert collected["signal"] == "ctrl" and collected["n_signals"] == 3 and collected["samples"] == 600
    assert_ok(run_cli("synergies", "fit", tmp_path / "commands", "--n-synergies", "2", "--out", tmp_path / "sar"))
    run = tmp_path / "sar-rl"
    # --import anywhere on the line; the module registers two ids, the plain one is used
    assert_ok(run_cli("train", "ArmReachHeavy-v0", "--import", "userpkg.arm", "--sar", tmp_path / "sar" / "sar.npz",
                      *TINY_PPO, "--out", run, "--no-progress"))
    trained = read_summary(run)
    assert trained["timesteps"] == 256 and trained["eval_episode_length_mean"] == 100
    assert trained["env_id"] == "ArmReachHeavy-v0"
    assert json.loads((run / "environment.json").read_text())["imports"] == ["userpkg.arm"]
    policy = json.loads((run / "policy.json").read_text())
    assert policy["action_space"]["shape"] == [2]  # the policy acts in the 2 synergies of the arm's 3 motors
    assert_ok(run_cli("evaluate", run, "--episodes", "2", "--out", tmp_path / "eval"))
    assert read_summary(tmp_path / "eval")["env_id"] == "ArmReachHeavy-v0"


def test_errors_name_the_module_and_what_went_wrong(tmp_path):
    out = tmp_path / "x"
    assert_one_line_error(run_cli("train", "nopkg.envs:Arm-v0", "--out", out),
                          "cannot import module 'nopkg.envs'", "ModuleNotFoundError", "nopkg")
    assert_one_line_error(run_cli("train", "userpkg.needs_missing:Arm-v0", "--out", out),
                          "cannot import module 'userpkg.needs_missing'", "motorlab_no_such_dependency")
    assert_one_line_error(run_cli("train", "userpkg.arm:ArmRech-v0", "--out", out),
                          "registers no env 'ArmRech-v0'", "it registers ArmReach-v0, ArmReachHeavy-v0")
    assert_one_line_error(run_cli("train", "userpkg.broken:WrongShape-v0", "--out", out),
                          "Gymnasium's env checker rejects it", "not within the observation space")
    assert_one_line_error(run_cli("evaluate", "pid", "--env", "ArmReach-v0", "--out", out),
                          "unknown env id 'ArmReach-v0'", "--import MODULE")
    assert_one_line_error(run_cli("train", ARM, "--import"), "--import needs a module name")
    assert_one_line_error(run_cli("--import", "nopkg", "run", "pendulum", "--check"),
                          "cannot import module 'nopkg' (given with --import)")
    assert not out.exists()  # nothing was started


RECIPE = """
name = "own-arm"
description = "a user's arm: PPO on two seeds, evaluated, transferred zero-shot to the heavy arm"
imports = ["userpkg.arm"]

[defaults]
env = "ArmReach-v0"
episodes = 2

[[steps]]
name = "ppo"
kind = "train"
algo = "ppo"
timesteps = 256
seeds = [0, 1]
hyperparams = { n_steps = 128, batch_size = 64 }

[[steps]]
name = "ppo-eval"
kind = "evaluate"
policy = "@ppo"

[[steps]]
name = "heavy"
kind = "zeroshot"
runs = ["@ppo"]
envs = ["ArmReachHeavy-v0"]
episodes = 2
"""


def test_recipe_with_imports(tmp_path):
    path = tmp_path / "own-arm.toml"
    path.write_text(RECIPE)
    proc = run_cli("run", path, "--out", tmp_path / "study")  # the seeds train in their own processes
    assert_ok(proc)
    s = read_summary(tmp_path / "study")
    assert s["ppo.seeds"] == 2 and s["ppo-eval.seeds"] == 2
    # both seeds on the heavy arm; the arm flags no success and has no maximum return: its success is no
    # number ("–"), never 0%, and no mean of it is made
    returns = [v for k, v in s.items() if k.startswith("heavy.") and k.endswith(".ArmReachHeavy-v0.return_mean")]
    assert len(returns) == 2 and all(math.isfinite(r) for r in returns), s
    assert all(v is None for k, v in s.items() if k.startswith("heavy.") and k.endswith(".success_rate"))
    assert "heavy.ppo.ArmReachHeavy-v0.success_rate_mean" not in s
    for seed in (0, 1):
        env = json.loads((tmp_path / "study" / "ppo" / f"seed{seed}" / "environment.json").read_text())
        assert env["imports"] == ["userpkg.arm"]
    assert_one_line_error(run_cli("run", _without_imports(path), "--check"), "unknown env id 'ArmReach-v0'")


def _without_imports(path: Path) -> Path:
    bare = path.with_name("bare.toml")
    bare.write_text(path.read_text().replace('imports = ["userpkg.arm"]', ""))
    return bare


def test_sweep_of_a_users_env(tmp_path):
    """On a pool of processes here; on a Ray cluster: tests/sweeps/test_sweep.py, beside the other Ray sweep."""
    command = f"train {ARM} " + " ".join(TINY_PPO)
    assert_ok(run_cli("sweep", command, "--seeds", "2", "--out", tmp_path / "local"))
    assert sorted(s["seed"] for s in _trained(tmp_path / "local")) == [0, 1]


def _trained(folder: Path) -> list[dict]:
    """summary.json of every training run under a sweep folder."""
    found = [json.loads(p.read_text()) for p in sorted(folder.rglob("summary.json"))]
    return [s for s in found if "algo" in s]
