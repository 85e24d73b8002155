"""A user's code failing (issue 52): an env whose step raises mid-run, in this process or in an
env worker; a --reward function that raises; an env with no time limit; a tampered policy.json;
spaces no motorlab policy reads; and the numbers that used to lie about it ("0%" success for an
env with no success flag, "inf ± nan" returns). Each failure is one line `error: ...` naming the
env, function or file, exit status 2, and the files already written stay as they were."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

import motorlab.envs.making
from motorlab.envs import EnvConfig
from motorlab.evaluation.rollouts import evaluate
from motorlab.policies import RandomPolicy, ZeroPolicy
from motorlab.report.results import Metric
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_here, snapshot

MODULE = "usercode_envs"
SOURCE = '''
import gymnasium as gym
import numpy as np


class UserEnv(gym.Env):
    """Box(3) observations; `boom`: the step that raises (counted over the env's life); `reward`:
    per step; `ends`: whether episodes end by themselves (after 20 steps)."""

    def __init__(self, boom=None, reward=1.0, ends=True, obs=None):
        self.observation_space = obs or gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.boom, self.reward, self.ends, self.steps, self.t = boom, reward, ends, 0, 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        self.observation_space.seed(int(self.np_random.integers(2**31)))
        return self.observation_space.sample(), {}

    def step(self, action):
        self.t += 1
        self.steps += 1
        if self.boom is not None and self.steps >= self.boom:
            raise RuntimeError("simulator diverged")
        return self.observation_space.sample(), self.reward, False, self.ends and self.t >= 20, {}


class NoWorkers(UserEnv):
    """Made in the trainer's own process only: in any other (an env worker) it cannot start, as an env
    tied to a licence, a display or a device may not."""

    def __init__(self, **kwargs):
        import multiprocessing

        if multiprocessing.parent_process() is not None:
            raise OSError("the licence server refused a second process")
        super().__init__(**kwargs)


def bad_reward(obs, action, reward, terminated, info):
    raise ValueError("reward exploded")


gym.register("Boom-v0", entry_point=UserEnv, max_episode_steps=20, kwargs={"boom": 15})
gym.register("Huge-v0", entry_point=UserEnv, max_episode_steps=20, kwargs={"reward": 1e308})
gym.register("Endless-v0", entry_point=UserEnv, kwargs={"ends": False})
gym.register("Plain-v0", entry_point=UserEnv, max_episode_steps=20)
gym.register("NoWorkers-v0", entry_point=NoWorkers, max_episode_steps=20)
gym.register("Tuple-v0", entry_point=UserEnv, max_episode_steps=20,
             kwargs={"obs": gym.spaces.Tuple((gym.spaces.Box(-1, 1, (2,)), gym.spaces.Discrete(3)))})
gym.register("Image-v0", entry_point=UserEnv, max_episode_steps=20,
             kwargs={"obs": gym.spaces.Box(0, 255, (16, 16, 3), np.uint8)})
'''
LQR = ["--algo", "lqr", "--timesteps", "300", "--no-progress"]


@pytest.fixture(scope="module", autouse=True)
def user_module(tmp_path_factory):
    """The user's module on sys.path (env workers get this process's sys.path and its imports)."""
    import sys

    folder = tmp_path_factory.mktemp("usercode")
    (folder / f"{MODULE}.py").write_text(SOURCE)
    sys.path.insert(0, str(folder))
    yield folder
    sys.path.remove(str(folder))


def env(name: str) -> str:
    return f"{MODULE}:{name}"


# ---- spaces at the door -----------------------------------------------------------------------

@pytest.mark.parametrize(("name", "fragment"), [("Tuple-v0", "Tuple"), ("Image-v0", "an image")])
@pytest.mark.parametrize("command", [["train", *LQR], ["train", "--algo", "ppo", "--timesteps", "64"],
                                     ["evaluate", "random", "--episodes", "2"]])
def test_spaces_no_policy_reads_are_refused_before_any_file(tmp_path, name, fragment, command):
    out = tmp_path / "run"
    args = [*command, "--env", env(name)] if command[0] == "evaluate" else [command[0], env(name), *command[1:]]
    message = assert_one_line_error(run_here(*args, "--out", out), env(name), fragment, "FlattenObservation")
    assert "Traceback" not in message
    assert not out.exists() or not any(out.iterdir())


# ---- the env or the reward raising mid-run ------------------------------------------------------

def test_an_env_that_raises_mid_training_is_one_line_naming_it(tmp_path):
    out = tmp_path / "train"
    message = assert_one_line_error(run_here("train", env("Boom-v0"), *LQR, "--out", out),
                                    env("Boom-v0"), "step", "RuntimeError: simulator diverged", f"{MODULE}.py:")
    assert "fix it there" in message


def test_an_env_that_raises_in_a_training_env_worker_is_one_line_naming_it(tmp_path):
    """--n-envs 2: the env steps in SB3's SubprocVecEnv workers; its error still reaches the user as one
    line (not the worker's traceback and a closed pipe)."""
    out = tmp_path / "train"
    proc = run_here("train", env("Boom-v0"), "--algo", "ppo", "--timesteps", "256", "--n-envs", "2", "--set",
                    "n_steps=64", "--set", "batch_size=64", "--no-progress", "--out", out)
    assert_one_line_error(proc, "env worker", env("Boom-v0"), "RuntimeError: simulator diverged", f"{MODULE}.py:")
    assert "Traceback" not in proc.stderr + proc.stdout


def test_an_env_no_training_env_worker_can_make_is_one_line_naming_why(tmp_path):
    """--n-envs 2: a worker that cannot make its env stops before SB3 hears from it; the trainer says why in
    one line (the worker's error and where it was raised), not ConnectionResetError from a closed pipe."""
    proc = run_here("train", env("NoWorkers-v0"), "--algo", "ppo", "--timesteps", "256", "--n-envs", "2", "--set",
                    "n_steps=64", "--set", "batch_size=64", "--no-progress", "--out", tmp_path / "train")
    assert_one_line_error(proc, "env worker", "could not make its env", env("NoWorkers-v0"),
                          "OSError: the licence server refused a second process", f"{MODULE}.py:")
    assert "Traceback" not in proc.stderr + proc.stdout and "ConnectionResetError" not in proc.stderr + proc.stdout


@pytest.mark.parametrize("workers", ["1", "2"])
def test_an_env_that_raises_mid_evaluation_is_one_line_in_this_process_or_a_worker(tmp_path, workers):
    first = tmp_path / "first"
    assert_ok(run_here("evaluate", "zero", "--env", env("Plain-v0"), "--episodes", "2", "--out", first))
    before = snapshot(first)
    proc = run_here("evaluate", "zero", "--env", env("Boom-v0"), "--episodes", "4", "--workers", workers,
                    "--out", tmp_path / "second")
    assert_one_line_error(proc, env("Boom-v0"), "RuntimeError: simulator diverged", f"{MODULE}.py:")
    assert snapshot(first) == before  # files already written stay as they were


def test_a_reward_function_that_raises_is_one_line_naming_it(tmp_path):
    proc = run_here("train", env("Plain-v0"), *LQR, "--reward", f"{MODULE}:bad_reward", "--out", tmp_path / "r")
    assert_one_line_error(proc, f"--reward {MODULE}:bad_reward", "ValueError: reward exploded", f"{MODULE}.py:")


# ---- no time limit --------------------------------------------------------------------------------

def test_an_env_without_a_time_limit_stops_in_one_line_instead_of_hanging(tmp_path, monkeypatch):
    monkeypatch.setattr(motorlab.envs.making, "UNLIMITED_EPISODE_CAP", 200)  # 100,000 in real runs
    proc = run_here("evaluate", "zero", "--env", env("Endless-v0"), "--episodes", "2", "--workers", "1",
                    "--out", tmp_path / "e")
    assert_one_line_error(proc, env("Endless-v0"), "no time limit", "--env-arg max_episode_steps=N")
    # the fix the message gives works: Gymnasium's TimeLimit, through the env's own arguments
    out = tmp_path / "limited"
    assert_ok(run_here("evaluate", "zero", "--env", env("Endless-v0"), "--env-arg", "max_episode_steps=30",
                       "--episodes", "2", "--workers", "1", "--out", out))
    assert read_summary(out)["episode_lengths"] == [30, 30]


# ---- a tampered policy.json -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def ppo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ppo") / "run"
    assert_ok(run_here("train", ENV_ID, "--algo", "ppo", "--timesteps", "64", "--set", "n_steps=32",
                       "--set", "batch_size=32", "--no-progress", "--out", out))
    return out


@pytest.fixture(scope="module")
def lqr_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("lqr") / "run"
    assert_ok(run_here("train", ENV_ID, *LQR, "--out", out))
    return out


def _tamper(run, tmp_path, change) -> tuple:
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    meta = json.loads((copy / "policy.json").read_text())
    change(meta)
    (copy / "policy.json").write_text(json.dumps(meta))
    return copy, snapshot(copy)


SB3_TAMPERS = {
    "policy_class": lambda m: m.update(policy_class="EvilPolicy"),
    "policy_class ": lambda m: m.update(policy_class=["ActorCriticPolicy"]),
    "observation_space": lambda m: m.pop("observation_space"),
    "action_space": lambda m: m.update(action_space={"type": "Box", "shape": "x"}),
    "policy_kwargs": lambda m: m.update(policy_kwargs={"activation_fn": {"class": "torch.nn.NoSuchLayer"}}),
    "policy_kwargs ": lambda m: m.update(policy_kwargs={"activation_fn": {"class": "torch.nnx.Evil"}}),
}
LQR_TAMPERS = {
    "obs_dim": lambda m: m.update(obs_dim="three"),
    "K": lambda m: m.pop("K"),
    "low": lambda m: m.update(low={"a": 1}),
    "type": lambda m: m.update(type="evil"),
}


@pytest.mark.parametrize("key", list(SB3_TAMPERS))
def test_a_tampered_sb3_policy_json_is_one_line_naming_the_file_and_key(ppo_run, tmp_path, key):
    run, before = _tamper(ppo_run, tmp_path, SB3_TAMPERS[key])
    proc = run_here("evaluate", run, "--episodes", "1", "--out", tmp_path / "ev")
    assert_one_line_error(proc, "policy.json", repr(key.strip()) if key.strip() != "policy_kwargs" else "torch")
    assert snapshot(run) == before


@pytest.mark.parametrize("key", list(LQR_TAMPERS))
def test_a_tampered_lqr_policy_json_is_one_line_naming_the_file_and_key(lqr_run, tmp_path, key):
    run, before = _tamper(lqr_run, tmp_path, LQR_TAMPERS[key])
    proc = run_here("evaluate", run, "--episodes", "1", "--out", tmp_path / "ev")
    assert_one_line_error(proc, "policy.json", f"key {key!r}")
    assert snapshot(run) == before


def test_a_policy_json_that_is_not_an_object_is_one_line(lqr_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(lqr_run, run)
    (run / "policy.json").write_text("[1, 2]")
    assert_one_line_error(run_here("evaluate", run, "--out", tmp_path / "ev"), "policy.json", "list")


# ---- numbers with their meaning ---------------------------------------------------------------------

def test_success_is_none_where_the_env_has_no_success_flag():
    rollouts = evaluate(ZeroPolicy(*_spaces("Plain-v0")), EnvConfig(id=env("Plain-v0")), 3, seed=0, workers=1)
    assert rollouts.summary()["success_rate"] is None  # not 0%: nothing defines success here
    assert Metric("success_rate", "success", "percent").number(rollouts.summary()) is None
    # where the task defines it (InvertedPendulum: return 1000), it is still a rate
    pendulum = evaluate(ZeroPolicy(*_spaces(ENV_ID)), EnvConfig(id=ENV_ID), 2, seed=0, workers=1).summary()
    assert pendulum["success_rate"] == 0.0


def test_a_non_finite_return_is_a_counted_fault_left_out_of_the_mean():
    rollouts = evaluate(RandomPolicy(_spaces("Huge-v0")[0], seed=0), EnvConfig(id=env("Huge-v0")), 3, seed=0,
                        workers=1)
    summary = rollouts.summary()
    assert np.isinf(rollouts.returns).all()  # 20 steps of 1e308 overflow the sum
    assert summary["numerical_faults"] == 3 and len(rollouts.fault_log) == 3
    assert "non-finite return" in rollouts.fault_log[0]
    assert summary["return_mean"] is None and summary["return_std"] is None  # not "inf ± nan"
    text = Metric("return_mean", "return", "return", spread="return_std").number(
        {"return_mean": 5.0, "return_std": float("nan")}).text
    assert text == "5.0"  # a spread that is not a number is not shown


def _spaces(name: str) -> tuple:
    from motorlab.envs import make_env

    made = make_env(EnvConfig(id=name if ":" in name else env(name) if name != ENV_ID else ENV_ID))
    try:
        return made.action_space, None
    finally:
        made.close()
