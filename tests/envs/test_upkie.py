"""Upkie wheeled biped (upkie 13, PyBullet backend): motorlab's env defaults, the
balancing reward, one-env-per-process isolation, PID, delay/history, a tiny PPO run
with parallel envs (in the recipe's study), evaluation (episode length, falls), video,
and bad inputs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from motorlab.envs import EnvConfig, LowPassDelay, make_env
from motorlab.envs.isolated import ProcessEnv
from motorlab.envs.upkie import balance_reward
from motorlab.errors import MotorlabError
from motorlab.evaluation import evaluate
from motorlab.policies import load_policy
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli

UPKIE = "Upkie-PyBullet-Pendulum"
TILTED = {"init_rand": {"pitch": 0.1}}  # episodes start from pitches drawn in [-0.1, 0.1] rad


def _rollout(env, actions, seed=0):
    obs = [env.reset(seed=seed)[0]]
    rewards = []
    for a in actions:
        o, r, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
        obs.append(o)
        rewards.append(r)
        if terminated or truncated:
            break
    return np.array(obs), np.array(rewards), info


def test_env_is_headless_unthrottled_200hz_with_10s_limit():
    import pybullet

    env = make_env(EnvConfig(id=UPKIE))
    try:
        env.reset(seed=0)
        base = env.unwrapped
        assert type(base).__name__ == "UpkieServos"
        assert base.dt == pytest.approx(0.005)
        assert env.spec.max_episode_steps == 2000
        assert pybullet.getConnectionInfo(0)["connectionMethod"] == pybullet.DIRECT  # no GUI
        assert base._UpkieEnv__rate is None  # no real-time rate limiter
        assert env.observation_space.shape == (4,) and env.action_space.shape == (1,)
    finally:
        env.close()
    assert not pybullet.isConnected(0)  # closing frees the process's PyBullet slot


def test_settings_change_frequency_and_time_limit():
    env = make_env(EnvConfig(id=UPKIE, kwargs={"frequency": 100.0, "time_limit": 0.5}))
    try:
        assert env.unwrapped.dt == pytest.approx(0.01)
        assert env.spec.max_episode_steps == 50
        obs, _, info = _rollout(env, [0.0] * 100)  # standing still, it takes over a second to tip over
        assert len(obs) == 51 and info["success"] and not info["fell"]
    finally:
        env.close()


def test_second_env_runs_in_its_own_process_and_matches_the_first():
    cfg = EnvConfig(id=UPKIE, kwargs=TILTED)
    first, second = make_env(cfg), make_env(cfg)
    try:
        assert not isinstance(first.unwrapped, ProcessEnv) and isinstance(second.unwrapped, ProcessEnv)
        actions = np.sin(np.arange(150) / 10.0)
        obs1, rew1, _ = _rollout(first, actions, seed=3)
        obs2, rew2, _ = _rollout(second, actions, seed=3)
        np.testing.assert_array_equal(obs1, obs2)
        np.testing.assert_array_equal(rew1, rew2)
        assert abs(obs1[0, 0]) > 0  # the seed drew a tilted start
    finally:
        first.close()
        second.close()


def test_balance_reward_values():
    assert balance_reward(0.0, 0.0, fell=False) == pytest.approx(2.0)
    assert balance_reward(0.1, 0.0, fell=False) == pytest.approx(1.5 + 0.5 * np.exp(-1))
    assert balance_reward(0.0, 0.5, fell=False) == pytest.approx(1.5 + 0.5 * np.exp(-1))
    assert balance_reward(-0.2, -1.0, fell=False) == pytest.approx(1.0 + 0.5 * np.exp(-4) + 0.5 * np.exp(-4))
    assert balance_reward(0.0, 0.0, fell=True) == 0.0


def test_env_reward_is_the_balance_reward_of_the_true_state():
    env = make_env(EnvConfig(id=UPKIE))
    try:
        env.reset(seed=0)
        for a in (0.5, 0.5, -0.2):
            _, r, terminated, _, info = env.step(np.array([a], dtype=np.float32))
            spine = info["spine_observation"]
            expected = balance_reward(spine["base_orientation"]["pitch"], spine["wheel_odometry"]["velocity"],
                                      terminated)
            assert r == pytest.approx(expected) and 1.0 < r < 2.0
    finally:
        env.close()


def test_pid_balances_the_whole_episode_where_doing_nothing_falls():
    cfg = EnvConfig(id=UPKIE, kwargs=TILTED)
    probe = make_env(cfg)
    pid, zero = load_policy("pid", probe, UPKIE), load_policy("zero", probe, UPKIE)
    probe.close()
    balanced = evaluate(pid, cfg, episodes=2, seed=0)  # 2000 steps each
    np.testing.assert_array_equal(balanced.lengths, 2000)
    assert balanced.falls == 0 and balanced.success.all()
    assert (balanced.returns > 3500).all()  # upright and still most of the time, not just alive
    fallen = evaluate(zero, cfg, episodes=2, seed=0)
    assert fallen.falls == 2 and (fallen.lengths < 2000).all() and not fallen.success.any()
    assert fallen.summary()["falls"] == 2


def test_delay_and_history_wrap_upkie():
    cfg = EnvConfig(id=UPKIE, delay=0.05, delay_on="action", history=3)
    env = make_env(cfg)
    try:
        delay = env
        while not isinstance(delay, LowPassDelay):
            delay = delay.env
        assert delay.alpha == pytest.approx(0.005 / 0.05)
        assert env.observation_space.shape == (12,)
        obs, _ = env.reset(seed=0)
        assert obs.shape == (12,)
        obs, *_ = env.step(np.array([3.0], dtype=np.float32))
        # the commanded 3 m/s reaches the wheels as 10% of it after one step
        assert delay._action[0] == pytest.approx(0.3)
    finally:
        env.close()


def test_video_of_a_pid_episode(tmp_path):
    import imageio.v2 as imageio

    assert_ok(run_cli("evaluate", "pid", "--env", UPKIE, "--env-arg", "time_limit=0.5", "--episodes", "1",
                      "--out", tmp_path / "pid"))
    assert_ok(run_cli("video", tmp_path / "pid", "--episodes", "1"))
    path = tmp_path / "pid" / "videos" / "episode_0.mp4"
    reader = imageio.get_reader(path)
    frames = [f for f in reader]
    assert len(frames) == 26  # 100 steps at 200 Hz, every 4th step for 50 fps, and the last
    assert frames[0].shape == (480, 640, 3) and frames[0].std() > 10  # a scene, not a blank frame


@pytest.mark.parametrize("args, fragments", [
    (["--env-arg", "bogus=1"], ["does not take these settings", "bogus"]),
    (["--env-arg", "frequency=-5"], ["frequency must be a positive number"]),
    (["--env-arg", "time_limit=0"], ["time_limit must be a positive number"]),
    (["--env-arg", "time_limit"], ["--env-arg 'time_limit': write KEY=VALUE"]),
    (["--env-arg", 'init_rand={"yaw": 1}'], ["init_rand", "roll, pitch"]),
])
def test_bad_settings_give_one_line_errors(args, fragments):
    assert_one_line_error(run_cli("evaluate", "pid", "--env", UPKIE, "--episodes", "1", *args), *fragments)


def test_unknown_upkie_id_suggests_close_matches():
    assert_one_line_error(run_cli("evaluate", "pid", "--env", "Upkie-PyBullet-Pendulun"),
                          "unknown env id", "Upkie-PyBullet-Pendulum")


def test_only_rgb_array_rendering():
    with pytest.raises(MotorlabError, match="rgb_array"):
        make_env(EnvConfig(id=UPKIE), render_mode="human")


@pytest.mark.parametrize("missing, fragment", [("upkie", "need the upkie package"), ("pybullet", "needs pybullet")])
def test_missing_install_is_explained(missing, fragment):
    # A fresh interpreter where the package cannot be imported, as on a machine without it.
    code = (f"import sys; sys.modules[{missing!r}] = None; "
            "from motorlab.cli import main; "
            f"sys.argv = ['motorlab', 'evaluate', 'pid', '--env', {UPKIE!r}]; main()")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert_one_line_error(proc, fragment, "pip install upkie==13.1.0 pybullet==3.2.7")


def test_upkie_recipe_runs_end_to_end_on_tiny_budgets(tmp_path):
    """The bundled study on tiny budgets; its PPO step trains with two env processes, and its run
    folder is evaluated again from the command line."""
    import tomllib

    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from motorlab.recipes import bundled

    text = bundled()["upkie"].read_text()
    for old, new in [("timesteps = 150000", "timesteps = 512\nhyperparams = { n_steps = 128, batch_size = 64 }"),
                     ("eval_every = 50000", "eval_every = 256"), ("solve_episodes = 5", "solve_episodes = 2"),
                     ("episodes = 10", "episodes = 2"), ("episodes = 5", "episodes = 2"),
                     ('"delay=0:0.2:5", "obs-noise=0:0.04:5"', '"delay=0,0.2"'),
                     ("init_rand = { pitch = 0.1 } }", "init_rand = { pitch = 0.1 }, time_limit = 1.0 }")]:
        assert old in text
        text = text.replace(old, new)
    recipe = tmp_path / "upkie-tiny.toml"
    recipe.write_text(text)
    assert_ok(run_cli("run", recipe, "--out", tmp_path / "study"))
    s = read_summary(tmp_path / "study")
    assert s["steps"] == ["pid", "pid-on-delay", "pid-on-delay-both", "ppo", "ppo-eval", "ppo-on-delay",
                          "ppo-on-delay-both", "ppo-robust", "robustness", "video"]
    assert s["pid.falls"] == 0 and s["pid.episode_length_mean"] == 200  # 1 s episodes at 200 Hz
    for step in ("ppo-eval", "ppo-on-delay", "ppo-on-delay-both"):
        assert 0 <= s[f"{step}.falls"] <= 2 and 0 < s[f"{step}.episode_length_mean"] <= 200
    assert (tmp_path / "study" / "video" / "episode_0.mp4").stat().st_size > 1000
    assert not (tmp_path / "study" / "video" / "episode_1.mp4").exists()  # one video, not one per evaluation episode
    table = (tmp_path / "study" / "table.txt").read_text()
    assert "falls 0/2" in table and "video/episode_0.mp4" in table
    assert "delay 0.1 s on action" in table and "delay 0.1 s on both" in table

    # the ppo_balancer-like PPO trained with domain randomization, and the curves of all three balancers
    robust = tomllib.loads((tmp_path / "study" / "ppo-robust" / "config.toml").read_text())
    assert robust["env"]["delay"] == "0.05..0.15" and robust["env"]["history"] == 10
    assert robust["env"]["obs_noise"] == 0.01 and robust["env"]["kwargs"]["init_rand"]["pitch"] == 0.25
    curves = read_summary(tmp_path / "study" / "robustness")
    # success: Upkie's own flag, standing until the time limit
    assert curves["policies"] == ["pid", "ppo", "ppo-robust"] and curves["measure"] == "success"
    assert curves["curves"]["pid"]["delay"]["success_rate"][0] == 1  # PID stands without lag
    assert "robustness/plots/robustness.png" in (tmp_path / "study" / "report.html").read_text()

    run = tmp_path / "study" / "ppo"  # PPO with two env processes
    assert tomllib.loads((run / "config.toml").read_text())["n_envs"] == 2
    trained = read_summary(run)
    assert trained["timesteps"] >= 512 and trained["eval_episodes"] == 2
    assert trained["eval_falls"] + trained["eval_success_rate"] * 2 == pytest.approx(2)  # each episode: fell or stood
    assert 0 < trained["eval_episode_length_mean"] <= 200
    (events,) = (run / "tensorboard" / "PPO_1").glob("events.out.tfevents.*")  # SB3's own log
    tags = EventAccumulator(str(events)).Reload().Tags()["scalars"]
    assert "time/fps" in tags and "rollout/ep_len_mean" in tags
    proc = run_cli("evaluate", run, "--episodes", "2", "--delay", "0.05", "--delay-on", "action",
                   "--out", tmp_path / "eval")
    assert_ok(proc)
    e = read_summary(tmp_path / "eval")
    assert e["env_id"] == UPKIE and e["delay"] == 0.05 and e["episodes"] == 2
    assert e["falls"] == sum(n < 200 for n in e["episode_lengths"]) and max(e["episode_lengths"]) <= 200
    assert "falls" in proc.stdout
