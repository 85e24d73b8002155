"""A tiny training run writes every promised file; evaluate reads it back, pickle-free."""

from __future__ import annotations

import csv
import json
import math
import tomllib
import zipfile

import numpy as np
import pytest
from safetensors.numpy import load_file

from motorlab.policies import SB3Policy, load_run_policy
from motorlab.rl.monitor import METRIC_FIELDS
from tests.helpers import ENV_ID, TINY_PPO, assert_ok, assert_one_line_error, read_summary, run_cli, run_here

SB3_CLASSES = {"ppo": "PPO", "sac": "SAC", "td3": "TD3"}


def sb3_model(run_dir, algo: str):
    """SB3's own model from model.zip (this unpickles: tests only)."""
    import stable_baselines3

    return getattr(stable_baselines3, SB3_CLASSES[algo]).load(run_dir / "model.zip", device="cpu")


def observation_batch(n: int = 64, dim: int = 4, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(scale=0.5, size=(n, dim)).astype(np.float32)


def test_train_writes_config(ppo_run):
    config = tomllib.loads((ppo_run / "config.toml").read_text())
    assert config["algo"] == "ppo"
    assert config["timesteps"] == 256
    assert config["seed"] == 0
    assert config["env"]["id"] == ENV_ID
    assert config["hyperparams"] == {"n_steps": 128, "batch_size": 64}


def test_train_writes_metrics_csv(ppo_run):
    with open(ppo_run / "metrics.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = list(reader)
    assert reader.fieldnames == METRIC_FIELDS
    episodes = [r for r in rows if r["episode_return"]]
    evals = [r for r in rows if r["eval_return_mean"]]
    assert episodes and evals
    steps = [int(r["timesteps"]) for r in rows]
    assert steps == sorted(steps) and 0 < steps[-1] <= 256
    for r in episodes:
        # InvertedPendulum-v5 pays 1 per step except the terminating one.
        assert 0 <= float(r["episode_return"]) <= int(r["episode_length"])
    for r in evals:
        assert float(r["eval_return_min"]) <= float(r["eval_return_mean"]) <= 1000
        assert 0.0 <= float(r["eval_success_rate"]) <= 1.0


def test_train_writes_tensorboard_events(ppo_run):
    events = list((ppo_run / "tensorboard").rglob("events.out.tfevents.*"))
    folders = {e.parent.name for e in events}
    assert "motorlab" in folders  # motorlab's own eval/ scalars
    assert any(name.startswith("PPO") for name in folders)  # SB3's train/ scalars
    assert all(e.stat().st_size > 0 for e in events)


def test_train_writes_pickle_free_policy_and_model_zip(ppo_run):
    meta = json.loads((ppo_run / "policy.json").read_text())
    assert meta["type"] == "sb3" and meta["algo"] == "ppo"
    assert meta["observation_space"]["shape"] == [4] and meta["action_space"]["shape"] == [1]
    tensors = load_file(str(ppo_run / "policy.safetensors"))
    assert tensors and all(k.startswith(("policy.", "obs_rms.")) for k in tensors)
    assert zipfile.is_zipfile(ppo_run / "model.zip")


def test_train_writes_summary(ppo_run):
    s = read_summary(ppo_run)
    for key in ("steps_to_success", "solved", "wall_seconds", "timesteps", "budget", "eval_return_mean",
                "eval_return_std", "eval_return_min", "eval_success_rate", "eval_episode_lengths", "env_id", "algo"):
        assert key in s, key
    assert s["timesteps"] == s["budget"] == 256
    assert s["steps_to_success"] is None and s["solved"] is False  # not solved in 256 steps, not asked to stop
    assert s["wall_seconds"] > 0
    assert s["env_id"] == ENV_ID and s["algo"] == "ppo"
    assert len(s["eval_episode_lengths"]) == s["eval_episodes"] == 10
    assert s["eval_return_min"] <= s["eval_return_mean"] <= s["eval_return_max"] <= 1000
    assert not any(p.name.endswith(".tmp") for p in ppo_run.iterdir())  # atomic writes left no temp files


@pytest.mark.fast  # make test-fast: this workflow's end-to-end test
def test_evaluate_run_folder(ppo_run, tmp_path):
    out = tmp_path / "eval"
    proc = run_cli("evaluate", ppo_run, "--episodes", "3", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["episodes"] == 3
    assert len(s["episode_lengths"]) == 3 and all(n > 0 for n in s["episode_lengths"])
    assert s["return_min"] <= s["return_mean"] <= s["return_max"]
    assert s["return_std"] >= 0
    assert 0.0 <= s["success_rate"] <= 1.0
    assert s["env_id"] == ENV_ID
    assert tomllib.loads((out / "config.toml").read_text())["episodes"] == 3
    # Deterministic policy, seeded resets: a second evaluation gives the same numbers.
    out2 = tmp_path / "eval2"
    assert_ok(run_cli("evaluate", ppo_run, "--episodes", "3", "--out", out2))
    assert read_summary(out2)["episode_lengths"] == s["episode_lengths"]


def test_evaluate_on_delayed_env(ppo_run, tmp_path):
    out = tmp_path / "eval-delay"
    assert_ok(run_cli("evaluate", ppo_run, "--delay", "0.2", "--episodes", "2", "--out", out))
    s = read_summary(out)
    assert s["delay"] == 0.2 and s["episodes"] == 2
    assert tomllib.loads((out / "config.toml").read_text())["env"]["delay"] == 0.2


def test_pickle_free_policy_matches_sb3_predict(ppo_run):
    policy = load_run_policy(ppo_run)
    assert isinstance(policy, SB3Policy)
    obs = observation_batch()
    ours = policy.act(obs)
    theirs, _ = sb3_model(ppo_run, "ppo").predict(obs, deterministic=True)
    assert ours.shape == theirs.shape == (64, 1)
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-6)
    assert np.all(np.abs(ours) <= 3.0)


@pytest.mark.parametrize("algo", ["sac", "td3"])
def test_off_policy_run_writes_loadable_policy(algo, tmp_path):
    out = tmp_path / algo
    proc = run_cli("train", ENV_ID, "--algo", algo, "--timesteps", "300", "--set", "learning_starts=100",
                   "--no-progress", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["algo"] == algo and s["timesteps"] == 300
    meta = json.loads((out / "policy.json").read_text())
    assert meta["algo"] == algo
    policy = load_run_policy(out)
    obs = observation_batch(seed=1)
    theirs, _ = sb3_model(out, algo).predict(obs, deterministic=True)
    np.testing.assert_allclose(policy.act(obs), theirs, rtol=1e-5, atol=1e-6)
    assert np.all(np.abs(theirs) <= 3.0)


MAZE = "PointMaze_UMaze-v3"  # Gymnasium-Robotics: a goal-conditioned env (Dict observation), for --her
TINY_MAZE_SAC = ["--algo", "sac", "--timesteps", "200", "--eval-every", "200", "--solve-episodes", "2",
                 "--checkpoint-every", "0", "--env-arg", "continuing_task=false", "--env-arg", "max_episode_steps=50",
                 "--set", "learning_starts=100", "--set", "buffer_size=500", "--set", 'policy_kwargs={"net_arch":[16,16]}',
                 "--no-progress"]


def test_config_flags_are_judged_with_the_config(tmp_path):
    """`train --config SAC_RUN/config.toml --her`: --her is judged with the config's SAC (alone it would
    meet the default PPO); a flag overrides the config's value, a bad one is one line naming it."""
    sac = tmp_path / "sac"
    assert_ok(run_here("train", MAZE, *TINY_MAZE_SAC, "--out", sac))
    config = sac / "config.toml"
    assert tomllib.loads(config.read_text())["her"] is False
    her = tmp_path / "her"
    assert_ok(run_here("train", "--config", config, "--her", "--seed", "3", "--no-progress", "--out", her))
    again = tomllib.loads((her / "config.toml").read_text())
    assert (again["algo"], again["her"], again["seed"], again["env"]["id"]) == ("sac", True, 3, MAZE)
    assert {k: v for k, v in again.items() if k not in ("her", "seed")} == {
        k: v for k, v in tomllib.loads(config.read_text()).items() if k not in ("her", "seed")}
    assert read_summary(her)["algo"] == "sac" and read_summary(her)["seed"] == 3
    assert_one_line_error(run_here("train", "--config", config, "--seed", "-1", cwd=tmp_path), "--seed -1")
    assert_one_line_error(run_here("train", "--config", config, "--her", "--algo", "ppo", cwd=tmp_path), "--her", "PPO")
    assert not (tmp_path / "runs").exists()  # refused before a run folder was made


def test_normalized_run_applies_observation_statistics(tmp_path):
    out = tmp_path / "ppo-norm"
    assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--normalize", "--no-progress", "--out", out))
    meta = json.loads((out / "policy.json").read_text())
    assert meta["obs_norm"] is not None
    tensors = load_file(str(out / "policy.safetensors"))
    mean, var = tensors["obs_rms.mean"], tensors["obs_rms.var"]
    assert mean.shape == var.shape == (4,) and np.all(var > 0)
    policy = load_run_policy(out)
    obs = observation_batch(seed=2)
    # SB3's policy on observations normalized by hand with the saved statistics.
    normalized = np.clip((obs - mean) / np.sqrt(var + meta["obs_norm"]["epsilon"]),
                         -meta["obs_norm"]["clip_obs"], meta["obs_norm"]["clip_obs"]).astype(np.float32)
    theirs, _ = sb3_model(out, "ppo").predict(normalized, deterministic=True)
    np.testing.assert_allclose(policy.act(obs), theirs, rtol=1e-5, atol=1e-6)


def test_history_run_trains_and_evaluates_with_its_history(tmp_path):
    out = tmp_path / "ppo-hist"
    assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--history", "3", "--delay", "0.2", "--no-progress", "--out", out))
    s = read_summary(out)
    assert s["history"] == 3 and s["delay"] == 0.2
    assert json.loads((out / "policy.json").read_text())["observation_space"]["shape"] == [12]
    ev = tmp_path / "ev"
    assert_ok(run_cli("evaluate", out, "--episodes", "2", "--out", ev))  # the run's own env settings
    assert read_summary(ev)["history"] == 3


def test_evaluate_builtin_controllers(tmp_path):
    for spec, solved in [("pid", True), ("pid:kp=[1,20,0,0],kd=[1,3,0,0]", True), ("zero", False)]:
        out = tmp_path / spec.split(":")[0] / str(len(spec))
        assert_ok(run_cli("evaluate", spec, "--env", ENV_ID, "--episodes", "2", "--out", out))
        s = read_summary(out)
        assert s["policy"] == spec
        assert (s["success_rate"] == 1.0) is solved
        assert (s["return_min"] == 1000.0) is solved


def test_wall_seconds_is_a_positive_finite_number(ppo_run, fast_run):
    for run in (ppo_run, fast_run):
        w = read_summary(run)["wall_seconds"]
        assert isinstance(w, float) and math.isfinite(w) and w > 0
