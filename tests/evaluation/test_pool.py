"""Evaluation on every core: envs stepped in worker processes give the serial results number for
number (returns, lengths, success, falls, faults, traces), for built-in and users' envs, in
`evaluate`, `zeroshot` and `synergies collect`; a worker that raises or dies is one clear line,
and neither an error nor Ctrl-C leaves a worker behind."""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motorlab.controllers import save_controller
from motorlab.controllers.pid import make_pid
from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.evaluation import Evaluator, evaluate, pool
from motorlab.evaluation.zeroshot import transfer
from motorlab.kinds.evaluate import EVALUATE, ZEROSHOT
from motorlab.policies import RandomPolicy, load_policy
from motorlab.runs import write_json
from motorlab.user_modules import import_modules
from tests.helpers import ENV_ID, USER_PACKAGES, run_kind

ENVS_MODULE = "motorlab_pool_test_envs"  # a user's env module, written for these tests (workers import it)
ENVS_SOURCE = '''
import os

import gymnasium as gym
import numpy as np


class Mix(gym.Env):
    """Episodes whose end is drawn at reset: a fall (terminated), the time limit (12 steps:
    truncated), a NaN observation (a numerical fault); some are solved at step 2."""

    def __init__(self, render_mode=None):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.end = 0, int(self.np_random.integers(3, 16))
        self.kind = int(self.np_random.integers(3))  # 0: falls, 1: faults, 2: solved at step 2, then falls
        self.x = self.np_random.normal(size=3).astype(np.float32)
        return self.x.copy(), {}

    def step(self, action):
        self.t += 1
        self.x = (0.9 * self.x + float(action[0]) + 0.1 * self.np_random.normal(size=3)).astype(np.float32)
        obs, ended = self.x.copy(), self.t >= self.end
        if ended and self.kind == 1:
            obs[0] = np.nan
        return obs, float(self.x.sum()), ended, False, {"solved": self.kind == 2 and self.t == 2}


class Boom(gym.Env):
    """Raises (mode "raise") or exits (mode "exit") at step 2 of the episode reset with seed 1000003."""

    def __init__(self, mode="raise", render_mode=None):
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.mode = mode

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.armed = 0, seed == 1000003
        return np.zeros(2, np.float32), {}

    def step(self, action):
        self.t += 1
        if self.armed and self.t == 2:
            if self.mode == "exit":
                os._exit(3)
            raise RuntimeError("boom at step 2\\n(a second line)")
        return np.zeros(2, np.float32), 1.0, self.t >= 5, False, {}


gym.register("PoolMix-v0", entry_point=Mix, max_episode_steps=12)
gym.register("PoolBoom-v0", entry_point=Boom)
'''


@pytest.fixture(scope="module", autouse=True)
def user_envs(tmp_path_factory):
    """The test envs' module and tests/userpkg on sys.path (workers get this process's sys.path)."""
    folder = tmp_path_factory.mktemp("user_envs")
    (folder / f"{ENVS_MODULE}.py").write_text(ENVS_SOURCE)
    added = [str(folder), USER_PACKAGES]
    sys.path[:0] = added
    yield
    for path in added:
        sys.path.remove(path)


def same(a, b) -> None:
    """Two Rollouts hold the same numbers."""
    for key in ("returns", "lengths", "success"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    assert (a.falls, a.fault_log, a.dt, a.aborted) == (b.falls, b.fault_log, b.dt, b.aborted)
    assert len(a.observations) == len(b.observations) and len(a.actions) == len(b.actions)
    for x, y in zip(a.observations + a.actions, b.observations + b.actions, strict=True):
        assert x.dtype == y.dtype
        np.testing.assert_array_equal(x, y)


def no_workers_left() -> None:
    assert mp.active_children() == []


class Drifting:
    """A stateful policy (one row per episode) that acts on its observations."""

    def reset(self, n: int) -> None:
        self.t = np.zeros(n)

    def act(self, obs: np.ndarray) -> np.ndarray:
        self.t += 1
        return np.tanh(-0.5 * obs[:, :1] + 0.05 * self.t[:, None]).astype(np.float32)


def test_pendulum_parallel_equals_serial():
    cfg = EnvConfig(id=ENV_ID)
    env = make_env(cfg)
    for name in ("pid:kp=[0.2,2.5,0,0],ki=[0.01,0,0,0]", "random"):  # weak gains: episodes fall at different steps
        runs = [evaluate(load_policy(name, env, ENV_ID, seed=0), cfg, 10, seed=5, record=True, batch=4,
                         workers=workers) for workers in (1, 2)]
        same(*runs)
        assert runs[0].falls > 0 and len(set(runs[0].lengths)) > 1, name
    no_workers_left()


def test_user_env_parallel_equals_serial():
    cfg = EnvConfig(id=f"{ENVS_MODULE}:PoolMix-v0")
    serial = evaluate(Drifting(), cfg, 40, seed=11, record=True, batch=12, workers=1)
    # the mix covers every way an episode ends
    assert serial.falls > 0 and serial.faults > 0 and 0 < serial.success.sum() < 40 and (serial.lengths == 12).any()
    for workers in (2, 3):  # 12 envs in 2 or 3 slices, the last batch (4 episodes) on fewer
        same(serial, evaluate(Drifting(), cfg, 40, seed=11, record=True, batch=12, workers=workers))
    no_workers_left()


def test_userpkg_arm_parallel_equals_serial():
    import_modules(["userpkg.arm"])
    cfg = EnvConfig(id="ArmReach-v0")
    space = make_env(cfg).action_space
    runs = [evaluate(RandomPolicy(space, seed=1), cfg, 5, seed=0, record=True, batch=3, workers=w) for w in (1, 2)]
    same(*runs)


def test_evaluator_keeps_its_api_and_runs_in_processes():
    cfg = EnvConfig(id=ENV_ID)
    with Evaluator(cfg, episodes=4, seed=3) as serial, Evaluator(cfg, episodes=4, seed=3, workers=2) as parallel:
        assert (serial.workers, parallel.workers) == (1, 2)
        assert len(serial.envs) == 4 and parallel.observation_space == serial.observation_space
        assert parallel.dt == serial.dt > 0
        for stop_below in (None, 900.0):  # --until-solved stops at the first episode below it
            a, b = (ev.run(Drifting(), stop_below=stop_below) for ev in (serial, parallel))
            same(a, b)
        assert a.aborted
    no_workers_left()


# ---- zero-shot, the step kinds' settings, collect ----------------------------------------------

@pytest.fixture(scope="module")
def pid_run(tmp_path_factory) -> Path:
    """A finished run folder holding a (weak) PID controller for the pendulum."""
    run = tmp_path_factory.mktemp("runs") / "pid"
    run.mkdir()
    env = make_env(EnvConfig(id=ENV_ID))
    save_controller(run, make_pid("pid:kp=[0.2,2.5,0,0],ki=[0.01,0,0,0]", ENV_ID, 4, float(env.unwrapped.dt),
                                  env.action_space.low, env.action_space.high))
    (run / "config.toml").write_text(f'[env]\nid = "{ENV_ID}"\n')
    write_json(run / "summary.json", {})
    return run


def test_zeroshot_equal_for_workers_1_and_2(pid_run):
    envs = [ENV_ID, "InvertedPendulum-v4"]
    one, two = (transfer([pid_run], envs, episodes=6, seed=2, workers=w) for w in (1, 2))
    assert one.results == two.results and one.fault_log == two.fault_log
    assert one.results["pid"][ENV_ID]["falls"] > 0
    no_workers_left()


def test_evaluate_step_takes_workers(pid_run, tmp_path):
    fields = dict(policy=str(pid_run), episodes=4, seed=1)
    one = run_kind(EVALUATE, tmp_path / "one", workers=1, **fields)
    two = run_kind(EVALUATE, tmp_path / "two", workers=2, **fields)
    assert one.pop("run_dir") != two.pop("run_dir") and one == two
    for kind, passed in ((EVALUATE, fields), (ZEROSHOT, dict(runs=[str(pid_run)], envs=[ENV_ID]))):
        with pytest.raises(MotorlabError, match="workers"):
            kind.make(workers=0, **passed)
        assert kind.make(**passed).workers is None  # auto


def test_collect_does_not_depend_on_workers(pid_run, tmp_path):
    from motorlab.synergy_runs.activations import collect

    kwargs = dict(episodes=2, percentile=50.0, preview=3, seed=0, signal="ctrl", progress=False)
    one, two = (collect(pid_run, workers=w, **kwargs) for w in (1, 2))
    assert one.threshold == two.threshold and one.tried == two.tried
    np.testing.assert_array_equal(one.preview_returns, two.preview_returns)
    assert [e.seed for e in one.kept] == [e.seed for e in two.kept]
    np.testing.assert_array_equal(one.activations(), two.activations())


# ---- errors, Ctrl-C, the automatic choice --------------------------------------------------------

@pytest.mark.parametrize(("mode", "fragments"), [
    ("raise", ["env worker 2 of 2 (envs 3-5 of", "failed while stepping:", "RuntimeError: boom at step 2 (a second line)"]),
    ("exit", ["env worker 2 of 2 (envs 3-5 of", "stopped unexpectedly while stepping (exit code 3)"]),
])
def test_a_failing_worker_is_one_clear_line(mode, fragments):
    cfg = EnvConfig(id=f"{ENVS_MODULE}:PoolBoom-v0", kwargs={"mode": mode})
    with pytest.raises(MotorlabError) as caught:
        evaluate(Drifting(), cfg, 6, seed=1000000, workers=2)
    message = str(caught.value)
    assert "\n" not in message, message
    for fragment in fragments:
        assert fragment in message, message
    no_workers_left()


def test_a_worker_that_cannot_build_its_env_is_one_line():
    with pytest.raises(MotorlabError, match="unknown env id 'NoSuchEnv-v0'"):
        evaluate(Drifting(), EnvConfig(id="NoSuchEnv-v0"), 4, seed=0, workers=2)
    no_workers_left()


class Interrupting(Drifting):
    """Ctrl-C in the parent on its third step."""

    def act(self, obs):
        if self.t[0] == 2:
            self.pids = [p.pid for p in mp.active_children()]
            raise KeyboardInterrupt
        return super().act(obs)


def test_ctrl_c_leaves_no_worker_behind():
    policy = Interrupting()
    with pytest.raises(KeyboardInterrupt):
        evaluate(policy, EnvConfig(id=ENV_ID), 4, seed=0, workers=2)
    assert len(policy.pids) == 1  # workers=2: this process and one child
    no_workers_left()
    for pid in policy.pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_auto_stays_serial_for_small_work(monkeypatch):
    cfg = EnvConfig(id=ENV_ID)
    monkeypatch.setattr(pool, "available_cores", lambda: 2)
    assert pool.auto_workers(cfg, episodes=10, size=10) == 1  # 10 pendulum episodes: ~0.3 s of stepping
    assert pool.auto_workers(cfg, episodes=2000, size=50) == 2  # ~70 s
    assert pool.auto_workers(cfg, episodes=2000, size=1) == 1
    monkeypatch.setattr(pool, "available_cores", lambda: 1)
    assert pool.auto_workers(cfg, episodes=2000, size=50) == 1


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(slow=st.sets(st.integers(0, pool.PROBE_STEPS - 1), max_size=pool.PROBE_STEPS // 2 - 1),
       stall=st.floats(0.01, 1.0))
def test_auto_is_not_fooled_by_a_few_preempted_probe_steps(monkeypatch, slow, stall):
    """Fewer than half the probe steps stalled (a busy machine preempting this process) leave the
    choice as an idle machine makes it: the estimate is the probe's median step."""
    clock, calls = [0.0], [0]

    def perf_counter():  # each step's start then end; a step in `slow` takes `stall` s, the others 35 us
        calls[0] += 1
        step, is_end = divmod(calls[0] - 1, 2)
        if is_end:
            clock[0] += stall if step in slow else 35e-6
        return clock[0]

    monkeypatch.setattr(pool, "available_cores", lambda: 2)
    monkeypatch.setattr(pool.time, "perf_counter", perf_counter)
    assert pool.auto_workers(EnvConfig(id=ENV_ID), episodes=10, size=10) == 1
    calls[0] = 0
    assert pool.auto_workers(EnvConfig(id=ENV_ID), episodes=2000, size=50) == 2


class LocalEnv(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action):
        return np.zeros(2, np.float32), 1.0, True, False, {}


def test_workers_fork_only_from_a_process_running_one_thread():
    import threading

    assert pool._context().get_start_method() == ("fork" if threading.active_count() == 1 else "forkserver")
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert pool._context().get_start_method() == "forkserver"
    finally:
        stop.set()
        other.join()


def test_auto_falls_back_to_this_process_for_an_env_only_it_knows(monkeypatch):
    """An env registered in this process only (not by a module workers import) still evaluates:
    forked workers (this process runs one thread) inherit the registration; workers from the fork
    server (a process with threads) cannot build it, and auto falls back to this process."""
    gym.register("PoolLocal-v0", entry_point=LocalEnv)
    monkeypatch.setattr(pool, "CROSSOVER_S", 0.0)  # auto would use every core
    monkeypatch.setattr(pool, "available_cores", lambda: 2)
    fork, forkserver = mp.get_context("fork"), mp.get_context("forkserver")
    monkeypatch.setattr(pool, "_context", lambda: fork)
    assert list(evaluate(Drifting(), EnvConfig(id="PoolLocal-v0"), 4, seed=0, workers=2).returns) == [1.0] * 4
    monkeypatch.setattr(pool, "_context", lambda: forkserver)
    result = evaluate(Drifting(), EnvConfig(id="PoolLocal-v0"), 4, seed=0)
    assert list(result.returns) == [1.0] * 4
    with pytest.raises(MotorlabError, match="PoolLocal-v0"):  # asked for workers: told why they failed
        evaluate(Drifting(), EnvConfig(id="PoolLocal-v0"), 4, seed=0, workers=2)
    no_workers_left()


def test_kept_workers_serve_the_next_evaluations():
    """zeroshot evaluates env after env in the same child processes (keep_workers)."""
    mix = EnvConfig(id=f"{ENVS_MODULE}:PoolMix-v0")
    with pool.keep_workers():
        with Evaluator(EnvConfig(id=ENV_ID), episodes=4, seed=0, workers=2) as first:
            pids = [p.pid for p in first.pool._procs]
        with Evaluator(mix, episodes=6, seed=0, workers=2) as second:
            assert [p.pid for p in second.pool._procs] == pids
            kept = second.run(Drifting())
        assert [p.pid for p in mp.active_children()] == pids
    no_workers_left()
    with Evaluator(mix, episodes=6, seed=0) as serial:
        same(serial.run(Drifting()), kept)


@pytest.mark.parametrize("spec", ["pid", "random"])
def test_an_episode_is_the_same_alone_or_after_others_on_its_env(spec):
    """Each env runs its episodes back to back (a row restarts as soon as its episode ends): the
    policy's state is restarted for that row alone, so every episode equals itself run alone."""
    cfg = EnvConfig(id=ENV_ID, obs_noise="0..0.08")  # episodes of many lengths: some fall early, some last
    probe = make_env(cfg)

    def policy():
        return load_policy(spec, probe, ENV_ID, seed=0)

    together = evaluate(policy(), cfg, 9, seed=3, batch=3, workers=1)
    assert len(set(together.lengths)) > 2
    if spec == "pid":  # a random policy's draws depend on the batch, PID's output does not
        alone = [evaluate(policy(), cfg, 1, seed=3 + i, workers=1) for i in range(9)]
        assert list(together.returns) == [a.returns[0] for a in alone]
    assert together.returns.tolist() == evaluate(policy(), cfg, 9, seed=3, batch=3, workers=2).returns.tolist()
