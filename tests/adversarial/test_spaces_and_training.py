"""A demanding user's adversarial tries at training and policies (issue 35), each a test: Dict
observations (goal-conditioned tasks), Discrete actions, hindsight relabelling misused, videos of
envs that cannot render. A refusal is the exit status 2, one line with no traceback, and no file
written before the mistake changed (checksums before and after); what used to crash now works.

`--her` is a training setting the CLI's train command does not have a flag for yet: it is tried
through the Python API (the recipe and sweep path, TrainConfig) and through a recipe."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from motorlab.errors import MotorlabError
from motorlab.runs import read_config
from tests.helpers import (
    ENV_ID,
    assert_ok,
    assert_one_line_error,
    read_summary,
    run_cli,
    run_here,
    run_kind,
    snapshot,
)

MAZE = "PointMaze_UMaze-v3"  # Gymnasium-Robotics: a Dict observation (achieved_goal, desired_goal, observation)
CARTPOLE = "CartPole-v1"  # Discrete(2) actions, no MuJoCo
TINY_SAC = ["--algo", "sac", "--timesteps", "300", "--set", "learning_starts=100",
            "--set", 'policy_kwargs={"net_arch":[16,16]}', "--no-progress"]
TINY_DISCRETE = ["--algo", "ppo", "--timesteps", "512", "--set", "n_steps=128", "--set", "batch_size=64",
                 "--no-progress"]


@pytest.fixture(scope="module")
def maze_run(tmp_path_factory) -> Path:
    """SAC on the maze's Dict observation, with per-key normalization: what used to be "bad
    hyperparameters for SAC (You must use MultiInputPolicy ...)"."""
    out = tmp_path_factory.mktemp("maze") / "sac"
    assert_ok(run_here("train", MAZE, *TINY_SAC, "--normalize", "--out", out))
    return out


@pytest.fixture(scope="module")
def cartpole_run(tmp_path_factory) -> Path:
    """PPO on Discrete actions: what used to train its whole budget and crash at save."""
    out = tmp_path_factory.mktemp("cartpole") / "ppo"
    assert_ok(run_here("train", CARTPOLE, *TINY_DISCRETE, "--out", out))
    return out


# ---- what used to crash now works -------------------------------------------------------

def test_sac_on_a_dict_env_trains_a_multi_input_policy(maze_run):
    summary = read_summary(maze_run)
    assert summary["timesteps"] == 300 and summary["eval_episodes"] == 10
    meta = json.loads((maze_run / "policy.json").read_text())
    assert meta["policy_class"] == "SACMultiInputPolicy"
    assert meta["observation_space"]["type"] == "Dict"
    assert [s["key"] for s in meta["obs_layout"]] == ["achieved_goal", "desired_goal", "observation"]
    assert meta["obs_norm"]["keys"] == ["achieved_goal", "desired_goal", "observation"]
    proc = run_here("evaluate", maze_run, "--episodes", "3", "--out", maze_run.parent / "ev")
    assert_ok(proc)
    assert read_summary(maze_run.parent / "ev")["episodes"] == 3


def test_lqr_on_a_dict_env_learns_on_the_flat_observation(tmp_path):
    out = tmp_path / "lqr"
    assert_ok(run_here("train", MAZE, "--algo", "lqr", "--timesteps", "400", "--no-progress", "--out", out))
    meta = json.loads((out / "policy.json").read_text())
    assert meta["obs_dim"] == 8  # achieved_goal (2) + desired_goal (2) + observation (4)
    assert_ok(run_here("evaluate", out, "--episodes", "2", "--out", tmp_path / "ev"))
    assert read_summary(tmp_path / "ev")["episodes"] == 2


def test_ppo_on_discrete_actions_saves_evaluates_and_samples_randomly(cartpole_run, tmp_path):
    meta = json.loads((cartpole_run / "policy.json").read_text())
    assert meta["action_space"] == {"type": "Discrete", "n": 2, "start": 0}
    assert (cartpole_run / "model.zip").is_file()
    assert read_summary(cartpole_run)["timesteps"] == 512
    assert_ok(run_here("evaluate", cartpole_run, "--episodes", "3", "--out", tmp_path / "ev"))
    lengths = read_summary(tmp_path / "ev")["episode_lengths"]
    assert len(lengths) == 3 and min(lengths) > 0
    # the random controller draws action indices
    assert_ok(run_here("evaluate", "random", "--env", CARTPOLE, "--episodes", "3", "--out", tmp_path / "random"))
    assert read_summary(tmp_path / "random")["episodes"] == 3


def test_resume_of_a_discrete_run_after_ctrl_c(tmp_path):
    """Interrupted with SIGINT (Ctrl-C) after a checkpoint, a Discrete PPO run continues to its budget."""
    out = tmp_path / "run"
    args = [CARTPOLE, "--algo", "ppo", "--timesteps", "8192", "--set", "n_steps=256", "--set", "batch_size=64",
            "--checkpoint-every", "1024", "--eval-every", "4096", "--solve-episodes", "3", "--no-progress",
            "--out", str(out)]
    # Python's SIGINT handling even if the test runner was started with SIGINT ignored (as background jobs are)
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "train", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    latest, at, deadline = out / "checkpoint" / "latest.json", 0, time.monotonic() + 180
    while proc.poll() is None and time.monotonic() < deadline and at < 2048:
        try:
            at = json.loads(latest.read_text())["steps"]
        except (OSError, ValueError):
            time.sleep(0.05)
    assert proc.poll() is None, f"training ended before the interrupt: {proc.communicate()}"
    proc.send_signal(signal.SIGINT)
    try:  # 120 s as the other Ctrl-C tests: CI's 2 cores run another test file beside this one
        _, stderr = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise AssertionError(f"no exit 120 s after Ctrl-C: {proc.communicate()}") from None
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert not (out / "summary.json").exists()
    at = json.loads(latest.read_text())["steps"]  # the last checkpoint before the interrupt
    assert_ok(run_cli("train", "--resume", out, "--no-progress"))
    summary = read_summary(out)
    assert summary["resumed_from"] == at >= 2048
    assert summary["timesteps"] == 8192
    assert json.loads((out / "policy.json").read_text())["action_space"]["type"] == "Discrete"


# ---- Discrete actions: what needs Box actions refuses before anything is written ------------

DISCRETE_TRAIN = [
    (["--algo", "sac"], ["SAC needs continuous (Box) actions", "CartPole-v1's actions are Discrete(2)",
                         "use --algo ppo"]),
    (["--algo", "td3"], ["TD3 needs continuous (Box) actions", "Discrete(2)", "--algo ppo"]),
    (["--algo", "lqr"], ["LQR", "Discrete(2)", "--algo ppo"]),
    (["--algo", "ppo", "--action-noise", "0.1"], ["--action-noise", "Discrete(2)"]),
    (["--algo", "ppo", "--latency", "2"], ["--latency on actions", "--latency-on observation"]),
    (["--algo", "ppo", "--delay", "0.2"], ["--delay on actions", "--delay-on observation"]),
    (["--algo", "ppo", "--sar", "synergies.npz"], ["--sar", "Discrete(2)"]),
]


@pytest.mark.parametrize("args, fragments", DISCRETE_TRAIN, ids=[" ".join(a) for a, _ in DISCRETE_TRAIN])
def test_training_what_needs_box_actions_on_discrete_actions(cartpole_run, tmp_path, args, fragments):
    before = snapshot(cartpole_run, tmp_path)
    out = tmp_path / "out"
    proc = run_here("train", CARTPOLE, *args, "--timesteps", "256", "--no-progress", "--out", out)
    assert_one_line_error(proc, *fragments)
    assert not out.exists()
    assert snapshot(cartpole_run, tmp_path) == before


@pytest.mark.parametrize("controller, fragments", [
    ("pid", ["the PID controller needs continuous (Box) actions", "Discrete(2)", "--algo ppo"]),
    ("zero", ["the zero policy needs continuous (Box) actions", "Discrete(2)", "random"]),
])
def test_box_controllers_on_discrete_actions(cartpole_run, tmp_path, controller, fragments):
    before = snapshot(cartpole_run, tmp_path)
    proc = run_here("evaluate", controller, "--env", CARTPOLE, "--episodes", "2", "--out", tmp_path / "ev")
    assert_one_line_error(proc, *fragments)
    assert not (tmp_path / "ev").exists()
    assert snapshot(cartpole_run, tmp_path) == before


def test_a_recipe_that_trains_sac_on_discrete_actions_fails_its_check(tmp_path):
    recipe = tmp_path / "discrete.toml"
    recipe.write_text(textwrap.dedent(f"""\
        name = "discrete"
        [[steps]]
        name = "sac"
        kind = "train"
        env = "{CARTPOLE}"
        algo = "sac"
        timesteps = 200
        """))
    before = snapshot(tmp_path)
    assert_one_line_error(run_here("run", recipe, "--check"), "sac", "SAC needs continuous (Box) actions",
                          "Discrete(2)")
    assert snapshot(tmp_path) == before


# ---- --her where it cannot relabel ----------------------------------------------------------

HER_MISUSE = [
    ({"algo": "ppo"}, ["--her", "PPO", "--algo sac"]),
    ({"algo": "lqr"}, ["--her", "LQR", "--algo sac"]),
    ({"env": ENV_ID}, ["--her needs a goal-conditioned env", "InvertedPendulum-v5", "Box(4,)"]),
    ({"history": 2}, ["--her", "--history 2"]),
    ({"obs_noise": 0.01}, ["--her", "--obs-noise"]),
    ({"reward": "alive"}, ["--her", "compute_reward", "--reward alive"]),
    ({"hyperparams": {"learning_starts": 10}}, ["learning_starts (10)", "300 steps"]),
    ({"hyperparams": {"replay_buffer_class": "x"}}, ["--her", "replay_buffer_class"]),
]


@pytest.mark.parametrize("fields, fragments", HER_MISUSE, ids=[json.dumps(f) for f, _ in HER_MISUSE])
def test_her_misuse_is_one_line_before_anything_is_written(maze_run, tmp_path, fields, fragments):
    from motorlab.kinds.train import TRAIN

    before = snapshot(maze_run, tmp_path)
    out = tmp_path / "out"
    settings = {"env": MAZE, "algo": "sac", "her": True, "timesteps": 400, "progress": False, **fields}
    with pytest.raises(MotorlabError) as e:
        run_kind(TRAIN, out, **settings)
    message = str(e.value)
    assert "\n" not in message and all(f in message for f in fragments), message
    assert not out.exists()
    assert snapshot(maze_run, tmp_path) == before


def test_her_misuse_in_a_recipe_is_one_line(tmp_path):
    recipe = tmp_path / "her.toml"
    recipe.write_text(textwrap.dedent(f"""\
        name = "her"
        [[steps]]
        name = "her"
        kind = "train"
        env = "{ENV_ID}"
        algo = "sac"
        her = true
        timesteps = 200
        """))
    before = snapshot(tmp_path)
    assert_one_line_error(run_here("run", recipe, "--check"), "--her needs a goal-conditioned env", ENV_ID)
    assert_one_line_error(run_here("run", recipe, "--out", tmp_path / "study"), "goal-conditioned")
    assert not (tmp_path / "study" / "her").exists()  # refused before the step's folder was made
    assert {k: v for k, v in snapshot(tmp_path).items() if k in before} == before


# ---- Gymnasium-Robotics: the envs that fail upstream, a missing extra -------------------------

def test_a_fetch_env_that_fails_inside_gymnasium_robotics_is_one_line(tmp_path):
    out = tmp_path / "out"
    proc = run_here("train", "FetchReach-v4", "--algo", "sac", "--timesteps", "200", "--no-progress", "--out", out)
    assert_one_line_error(proc, "FetchReach-v4", "inside Gymnasium-Robotics", "MuJoCo", "PointMaze_")
    assert not out.exists()


def test_a_maze_without_the_robotics_extra_names_the_pip_command(tmp_path):
    code = ("import sys\nsys.modules['gymnasium_robotics'] = None\nfrom motorlab.cli import main\n"
            f"sys.argv = ['motorlab', 'train', {MAZE!r}, '--out', {str(tmp_path / 'out')!r}]\nmain()\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
    assert_one_line_error(proc, f"{MAZE} needs Gymnasium-Robotics", "pip install 'motorlab[robotics]'",
                          "gymnasium-robotics==1.4.2")
    assert not (tmp_path / "out").exists()


# ---- videos of envs that cannot render ---------------------------------------------------------

NO_RENDER = '''
import gymnasium as gym
import numpy as np


class NoRender(gym.Env):
    """A user's env whose constructor takes no render_mode."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.np_random.uniform(-1, 1, 2).astype(np.float32), {}

    def step(self, action):
        self.t += 1
        obs = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        return obs, -float(abs(action[0])), False, self.t >= 20, {}


gym.register("NoRender-v0", entry_point=NoRender)
'''


def test_video_of_an_env_without_render_mode(tmp_path, monkeypatch):
    (tmp_path / "norender_env.py").write_text(NO_RENDER)
    monkeypatch.syspath_prepend(str(tmp_path))
    run = tmp_path / "ev"
    assert_ok(run_here("evaluate", "random", "--env", "norender_env:NoRender-v0", "--episodes", "2", "--out", run))
    before = snapshot(tmp_path)
    proc = run_here("video", run, "--episodes", "1")
    message = assert_one_line_error(proc, "norender_env:NoRender-v0 cannot render", "render_mode", "A video needs")
    assert "does not take these settings" not in message
    assert snapshot(tmp_path) == before  # no videos/ folder
    # a real env-argument mistake is still called what it is
    assert_one_line_error(run_here("evaluate", "random", "--env", ENV_ID, "--env-arg", "wings=3", "--out",
                                   tmp_path / "x"), "does not take these settings", "wings")


def test_video_of_a_classic_control_env_without_pygame(cartpole_run, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pygame", None)  # as where pygame is not installed: import fails
    before = snapshot(cartpole_run)
    assert_one_line_error(run_here("video", cartpole_run, "--episodes", "1"), "CartPole-v1 cannot render here",
                          "pygame")
    assert snapshot(cartpole_run) == before


def test_her_flag_on_the_command_line(tmp_path):
    out = tmp_path / "her"
    assert_ok(run_here("train", "PointMaze_UMaze-v3", "--algo", "sac", "--her", "--timesteps", "300",
                       "--env-arg", "max_episode_steps=50", "--set", "learning_starts=100",
                       "--set", 'policy_kwargs={"net_arch":[16,16]}', "--no-progress", "--out", out))
    assert read_config(out)["her"] is True
    assert_one_line_error(run_here("train", "InvertedPendulum-v5", "--algo", "sac", "--her",
                                   "--out", tmp_path / "x"), "goal-conditioned")
    assert not (tmp_path / "x").exists()
