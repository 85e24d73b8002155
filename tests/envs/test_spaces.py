"""Spaces beyond one Box, end to end (issue 35): Dict observations (goal-conditioned tasks:
MultiInputPolicy, per-key normalization, hindsight relabelling) and Discrete actions (PPO) through
train, resume, evaluate, video, robustness, zero-shot and export (folder and ONNX); and two
training fixes: "trained for" is the steps trained, and `run --check` checks hyperparameter names.

`--her` has no flag on the train command yet: it is trained through the Python API (TrainConfig),
which recipes and sweeps use too."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from motorlab.envs import EnvConfig, make_env
from motorlab.policies import load_run_policy
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_metrics_rows, read_summary, run_cli, run_here

MAZE = "PointMaze_UMaze-v3"
CARTPOLE = "CartPole-v1"
# the maze as a task that ends when the ball reaches its goal, in at most 50 steps
MAZE_ARGS = ["--env-arg", "continuing_task=false", "--env-arg", "max_episode_steps=50"]
KEYS = ["achieved_goal", "desired_goal", "observation"]  # the Dict's keys, in its (flattening) order


def flat_observations(env_cfg: EnvConfig, n: int, seed: int = 0) -> np.ndarray:
    """`n` observations of the env as evaluation gives them (a Dict flattened), from random actions."""
    env = make_env(env_cfg, shaped=False)
    env.action_space.seed(seed)
    obs, _ = env.reset(seed=seed)
    seen = []
    for _ in range(n):
        seen.append(np.asarray(obs, dtype=np.float32))
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            obs, _ = env.reset()
    env.close()
    return np.array(seen)


def onnx_actions(model: Path, obs: np.ndarray) -> np.ndarray:
    import onnxruntime as ort

    session = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
    return session.run(None, {"obs": obs})[0]


# ---- Dict observations: a policy trained on the Dict, given flat observations --------------

@pytest.fixture(scope="module")
def maze_run(tmp_path_factory) -> Path:
    """A tiny SAC run on the maze's Dict observation, normalized per key."""
    out = tmp_path_factory.mktemp("maze") / "sac"
    assert_ok(run_here("train", MAZE, *MAZE_ARGS, "--algo", "sac", "--timesteps", "400", "--normalize",
                       "--set", "learning_starts=100", "--set", 'policy_kwargs={"net_arch":[16,16]}',
                       "--no-progress", "--out", out))
    return out


def test_a_dict_policy_records_its_layout_and_normalizes_each_key(maze_run):
    from safetensors.numpy import load_file

    meta = json.loads((maze_run / "policy.json").read_text())
    assert meta["policy_class"] == "SACMultiInputPolicy"
    assert [(s["key"], s["start"], s["stop"]) for s in meta["obs_layout"]] == [
        ("achieved_goal", 0, 2), ("desired_goal", 2, 4), ("observation", 4, 8)]
    tensors = load_file(maze_run / "policy.safetensors")
    stats = {k: (tensors[f"obs_rms.{k}.mean"], tensors[f"obs_rms.{k}.var"]) for k in KEYS}
    policy = load_run_policy(maze_run)
    env_cfg = EnvConfig(id=MAZE, kwargs={"continuing_task": False, "max_episode_steps": 50})
    flat = flat_observations(env_cfg, 64)
    # the network on the Dict, each key normalized with its own statistics, by hand
    eps, clip = meta["obs_norm"]["epsilon"], meta["obs_norm"]["clip_obs"]
    by_key = {s["key"]: flat[:, s["start"]:s["stop"]] for s in meta["obs_layout"]}
    normalized = {k: np.clip((v - stats[k][0]) / np.sqrt(stats[k][1] + eps), -clip, clip).astype(np.float32)
                  for k, v in by_key.items()}
    expected, _ = policy.policy.predict(normalized, deterministic=True)
    np.testing.assert_allclose(policy.act(flat), expected, atol=1e-6)
    # the policy loaded from its files scores what the policy in training scored on the same episodes
    summary = read_summary(maze_run)
    _, rows = read_metrics_rows(maze_run)
    last = [r for r in rows if r["eval_return_mean"]][-1]
    assert int(float(last["timesteps"])) == summary["timesteps"] == 400
    assert float(last["eval_return_mean"]) == pytest.approx(summary["eval_return_mean"])


def test_a_dict_policy_through_every_command(maze_run, tmp_path):
    run = str(maze_run)
    assert_ok(run_here("evaluate", run, "--episodes", "4", "--out", tmp_path / "ev"))
    evaluated = read_summary(tmp_path / "ev")
    assert evaluated["episodes"] == 4 and evaluated["env_id"] == MAZE

    assert_ok(run_here("video", run, "--episodes", "1", "--width", "64", "--height", "64", "--out", tmp_path / "vid"))
    video = read_summary(tmp_path / "vid")
    assert Path(video["videos"][0]).stat().st_size > 1000 and video["frames"][0] > 1

    assert_ok(run_here("robustness", run, "--vary", "obs-noise=0,0.05", "--episodes", "2", "--out", tmp_path / "rob"))
    curve = read_summary(tmp_path / "rob")["curves"]["sac"]["obs_noise"]
    assert curve["values"] == [0, 0.05] and len(curve["return_mean"]) == 2

    assert_ok(run_here("zeroshot", run, "--envs", "PointMaze_Open-v3", "--episodes", "2", "--out", tmp_path / "zs"))
    assert read_summary(tmp_path / "zs")["sac.PointMaze_Open-v3.success_rate"] is not None

    assert_ok(run_here("export", run, "--out", tmp_path / "shared"))
    assert not (tmp_path / "shared" / "model.zip").exists()
    assert_ok(run_here("evaluate", tmp_path / "shared", "--episodes", "4", "--out", tmp_path / "ev-shared"))
    assert read_summary(tmp_path / "ev-shared")["episode_lengths"] == evaluated["episode_lengths"]
    assert read_summary(tmp_path / "ev-shared")["return_mean"] == evaluated["return_mean"]

    assert_ok(run_here("export", run, "--onnx", "--out", tmp_path / "onnx"))
    sidecar = json.loads((tmp_path / "onnx" / "policy.onnx.json").read_text())
    assert [s["key"] for s in sidecar["obs_layout"]] == KEYS
    assert sidecar["inputs"][0]["name"] == "obs" and sidecar["inputs"][0]["shape"] == ["batch", 8]
    assert sidecar["normalized"] and sidecar["max_abs_error"] <= sidecar["tolerance"] == 1e-5
    # onnxruntime on the flat observations the env gives, against the torch policy
    flat = flat_observations(EnvConfig(id=MAZE, kwargs={"continuing_task": False, "max_episode_steps": 50}), 100, 3)
    got = onnx_actions(tmp_path / "onnx" / "policy.onnx", flat)
    np.testing.assert_allclose(got, load_run_policy(maze_run).act(flat), atol=1e-5)


# ---- hindsight relabelling beats plain SAC on the maze's sparse reward ---------------------

# SAC on the U-maze as a task that ends at the goal (sparse reward: 1 there, 0 elsewhere), 50 steps
# at most, its start and goal cells drawn anew each episode. Measured on 2 cores (50 evaluation
# episodes, success = the ball reached its goal), HER's success against plain SAC's, seeds 0 / 1 / 2:
#   8000 steps, batch 512:  0.28 / 0.30 / 0.36  against  0.00 / 0.00 / -
#   8000 steps, batch 256:  0.12 / 0.32 / 0.36  against  0.00 / 0.00 / 0.00
#   6000 steps, batch 256:  0.04 / -  / -  (seeds 3, 4: 0.44, 0.48)  against  0.00 (seeds 3, 4: 0.00, 0.02)
# Plain SAC has not met a reward often enough to learn from it by then; HER relabels every episode
# with goals it did reach. One HER run takes ~45 s, a plain one ~30 s; two run at once.
HER_SEEDS = (0, 1)
HER_MARGIN = 0.15  # success HER must gain over plain SAC, on each seed
HER_CONFIG = f"""\
algo = "sac"
timesteps = 8000
eval_every = 8000
solve_episodes = 50
checkpoint_every = 0
hyperparams = {{ learning_starts = 200, buffer_size = 8000, learning_rate = 0.001, gamma = 0.95, tau = 0.05, \
batch_size = 512, train_freq = 2, gradient_steps = 1, policy_kwargs = {{ net_arch = [64, 64] }} }}
[env]
id = "{MAZE}"
kwargs = {{ continuing_task = false, max_episode_steps = 50 }}
"""


def test_her_beats_plain_sac_on_the_sparse_maze(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    def train(seed: int, her: bool) -> float:
        name = f"{'her' if her else 'sac'}-seed{seed}"
        config = tmp_path / f"{name}.toml"
        config.write_text(f"her = {str(her).lower()}\nseed = {seed}\n" + HER_CONFIG)
        assert_ok(run_cli("train", "--config", config, "--no-progress", "--out", tmp_path / name, timeout=600))
        summary = read_summary(tmp_path / name)
        assert summary["eval_episodes"] == 50 and summary["timesteps"] == 8000
        return summary["eval_success_rate"]

    runs = [(seed, her) for seed in HER_SEEDS for her in (True, False)]
    with ThreadPoolExecutor(2) as pool:  # one process per core
        success = dict(zip(runs, pool.map(lambda run: train(*run), runs)))
    for seed in HER_SEEDS:
        print(f"seed {seed}: success with HER {success[seed, True]:.2f}, without {success[seed, False]:.2f}")
    for seed in HER_SEEDS:
        assert success[seed, True] >= success[seed, False] + HER_MARGIN, success


def test_a_her_run_killed_resumes_with_its_replay_buffer(tmp_path):
    """A HER run (started from a config file: the train command has no --her flag) killed with SIGKILL
    continues from its checkpoint: HerReplayBuffer's Dict observations and episode bounds come back,
    the episodes it was recording closed."""
    from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

    from motorlab.rl.checkpoint import load_checkpoint
    from motorlab.rl.config import resolve
    from motorlab.rl.sb3 import build_model
    from motorlab.runs import read_config

    config = tmp_path / "her.toml"
    config.write_text(textwrap.dedent(f"""\
        algo = "sac"
        her = true
        timesteps = 1500
        checkpoint_every = 300
        eval_every = 1500
        solve_episodes = 3
        hyperparams = {{ learning_starts = 100, buffer_size = 2000, policy_kwargs = {{ net_arch = [16, 16] }} }}
        [env]
        id = "{MAZE}"
        kwargs = {{ continuing_task = false, max_episode_steps = 50 }}
        """))
    out = tmp_path / "her"
    at = _train_and_kill(["--config", str(config)], out, 600)
    folder = out / "checkpoint"
    record = json.loads((folder / "latest.json").read_text())
    model = build_model(resolve(read_config(out)), tmp_path / "scratch")
    load_checkpoint(out, model)
    rb = model.replay_buffer
    assert isinstance(rb, HerReplayBuffer) and model.num_timesteps == at
    with np.load(folder / record["files"]["buffer"]) as z:
        filled = rb.pos
        assert filled == int(z["pos"]) >= at - 1  # the checkpoint's step itself is stored after the callback
        for key in KEYS:
            np.testing.assert_array_equal(rb.observations[key][:filled], z[f"observations.{key}"])
        np.testing.assert_array_equal(rb.ep_start[:filled], z["ep_start"])
        assert (z["ep_length"] > 0).any()  # finished episodes: goals to relabel
    assert (rb.ep_length[:filled] > 0).all()  # the one being recorded is closed
    assert (rb._current_ep_start == rb.pos).all()
    model.get_env().close()
    resumed = run_cli("train", "--resume", out, "--no-progress")
    assert_ok(resumed)
    summary = read_summary(out)
    assert summary["resumed_from"] == at and summary["timesteps"] == 1500
    assert read_config(out)["her"] is True


# ---- Discrete actions: PPO through train, kill, resume, evaluate, export, ONNX, video ------------

def _train_and_kill(args: list[str], out: Path, at_least: int) -> int:
    """Start `motorlab train ARGS --out OUT`, SIGKILL it once a checkpoint at >= `at_least` steps exists;
    the checkpoint's step count."""
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "train", *args, "--no-progress", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    latest, at, deadline = out / "checkpoint" / "latest.json", 0, time.monotonic() + 240
    while proc.poll() is None and time.monotonic() < deadline and at < at_least:
        try:
            at = json.loads(latest.read_text())["steps"]
        except (OSError, ValueError):
            time.sleep(0.05)
    assert proc.poll() is None, f"training ended before the kill: {proc.communicate()}"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists()
    return json.loads(latest.read_text())["steps"]


def test_discrete_ppo_killed_resumes_and_exports(tmp_path):
    out = tmp_path / "ppo"
    at = _train_and_kill([CARTPOLE, "--algo", "ppo", "--timesteps", "8192", "--set", "n_steps=256", "--set",
                          "batch_size=64", "--checkpoint-every", "1024", "--eval-every", "4096", "--solve-episodes",
                          "3"], out, 2048)

    resumed = run_cli("train", "--resume", out, "--no-progress")
    assert_ok(resumed)
    assert f"resumed at {at:,} steps" in resumed.stdout
    summary = read_summary(out)
    assert summary["resumed_from"] == at and summary["timesteps"] == 8192
    assert summary["eval_return_mean"] > 30  # learned something: a random CartPole policy lasts ~20 steps

    assert_ok(run_here("evaluate", out, "--episodes", "3", "--out", tmp_path / "ev"))
    assert_ok(run_here("export", out, "--out", tmp_path / "shared"))
    assert_ok(run_here("evaluate", tmp_path / "shared", "--episodes", "3", "--out", tmp_path / "ev-shared"))
    assert read_summary(tmp_path / "ev-shared")["return_mean"] == read_summary(tmp_path / "ev")["return_mean"]

    assert_ok(run_here("export", out, "--onnx", "--out", tmp_path / "onnx"))
    sidecar = json.loads((tmp_path / "onnx" / "policy.onnx.json").read_text())
    assert sidecar["outputs"][0] == {**sidecar["outputs"][0], "name": "action", "shape": ["batch"], "dtype": "int64"}
    assert sidecar["action_space"] == "Discrete(2)" and sidecar["max_abs_error"] == 0.0
    flat = flat_observations(EnvConfig(id=CARTPOLE), 200, 5)
    got = onnx_actions(tmp_path / "onnx" / "policy.onnx", flat)
    assert got.dtype == np.int64 and got.shape == (200,)
    np.testing.assert_array_equal(got, load_run_policy(out).act(flat))
    assert len(set(got.tolist())) == 2  # both actions occur: the check compares a real decision


DISCRETE_PENDULUM = '''
import gymnasium as gym


def make(**kwargs):
    """InvertedPendulum with 5 force levels: Discrete actions on a MuJoCo body, which renders."""
    return gym.wrappers.DiscretizeAction(gym.make("InvertedPendulum-v5", max_episode_steps=100, **kwargs), bins=5)


gym.register("DiscretePendulum-v0", entry_point=make)
'''


def test_video_of_a_discrete_policy(tmp_path, monkeypatch):
    (tmp_path / "discrete_pendulum.py").write_text(DISCRETE_PENDULUM)
    monkeypatch.syspath_prepend(str(tmp_path))
    env_id = "discrete_pendulum:DiscretePendulum-v0"
    out = tmp_path / "ppo"
    assert_ok(run_here("train", env_id, "--algo", "ppo", "--timesteps", "256", "--set", "n_steps=128",
                       "--set", "batch_size=64", "--no-progress", "--out", out))
    assert json.loads((out / "policy.json").read_text())["action_space"]["n"] == 5
    assert_ok(run_here("video", out, "--episodes", "1", "--width", "64", "--height", "64", "--out", tmp_path / "vid"))
    video = read_summary(tmp_path / "vid")
    assert Path(video["videos"][0]).stat().st_size > 1000
    assert_ok(run_here("evaluate", out, "--episodes", "1", "--out", tmp_path / "ev"))
    assert video["returns"][0] == pytest.approx(read_summary(tmp_path / "ev")["return_mean"])  # the same episode


# ---- "trained for" is the steps trained ----------------------------------------------------

def test_trained_for_is_the_budget_when_an_evaluation_solved_before_the_end(tmp_path):
    """Without --until-solved, training goes on after an evaluation solved: `timesteps` (the
    report's "trained for") is every step trained, steps_to_success when it first solved."""
    out = tmp_path / "ppo"
    assert_ok(run_here("train", ENV_ID, "--algo", "ppo", "--timesteps", "3072", "--set", "n_steps=256",
                       "--set", "batch_size=64", "--solve-return", "20", "--solve-episodes", "2", "--no-progress",
                       "--out", out))
    summary = read_summary(out)
    assert summary["steps_to_success"] is not None and summary["steps_to_success"] < 3072, summary
    assert summary["timesteps"] == 3072
    _, rows = read_metrics_rows(out)
    assert max(float(r["timesteps"]) for r in rows if r["eval_return_mean"]) == 3072  # evaluated to the end
    results = json.loads((out / "results.json").read_text())
    trained = next(n for n in results["numbers"] if n["key"] == "timesteps")
    assert trained["value"] == 3072, trained


# ---- run --check checks what SB3 would refuse -----------------------------------------------

def test_check_rejects_an_unknown_hyperparameter(tmp_path):
    proc = run_here("run", "pendulum", "--check", "--set", "ppo.hyperparams={n_stepz=3}", cwd=tmp_path)
    assert_one_line_error(proc, "n_stepz", "did you mean n_steps")
    assert list(tmp_path.iterdir()) == []
    assert_ok(run_here("run", "pendulum", "--check", "--set", "ppo.hyperparams={n_steps=64}", cwd=tmp_path))
