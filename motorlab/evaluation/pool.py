"""Env pools: the envs of a batch of evaluation episodes, stepped in this process (`SerialPool`)
or over several processes (`ProcessPool`), behind one interface:

    with make_pool(env_cfg, size=50, workers=2) as pool:
        obs = pool.reset([seed + i for i in range(n)])   # the first n envs, stacked observations
        steps = pool.step(actions, active)               # the active rows' obs, rewards, flags

The policy stays in the caller's process: each step it acts on the whole batch; the pool sends
each child process the actions of its contiguous slice of the envs (only rows still in an
episode), steps the first slice itself, then receives from all (send to all, then receive from
all, as SB3's SubprocVecEnv). Env i always lives in the same place, so episode rows run on the
same env objects, in the same order, whatever the number of workers: the results are the serial
ones, number for number.

Why not Gymnasium's AsyncVectorEnv (checked against gymnasium 1.2.3): it starts one process per
env (50 processes for a batch of 50 on a 2-core machine); its step sends an action to every env
every step (no mask: an env whose episode ended is stepped or reset along with the rest); it
resets finished envs itself by default (autoreset NEXT_STEP; a DISABLED mode exists, but then
stepping a finished env is the caller's problem); and it pickles each env's whole `info` back
every step and merges them into one dict (MyoSuite's is ~2.5 kB per env, with nested obs and
reward dicts). Here a process holds a slice of envs, steps only the active ones, and sends back
only what evaluation reads (`Steps`).
"""

from __future__ import annotations

import contextlib
import contextvars
import multiprocessing as mp
import os
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np

from motorlab import processes
from motorlab.envs import EnvConfig, env_dt, facts, make_env
from motorlab.envs.catalog import SUCCESS_KEYS
from motorlab.envs.wrappers import UserCodeError
from motorlab.errors import MotorlabError
from motorlab.faults import fault_of
from motorlab.user_modules import adopt, imported_names


def step_success(info: dict, keys: tuple[str, ...] = SUCCESS_KEYS) -> bool | None:
    """The env's own success flag for this step (MyoSuite: info["solved"]), or None. `keys`: the
    info keys to read, in order (the env's catalogue entry's `success_keys`)."""
    for key in keys:
        if key in info:
            return bool(info[key])
    return None


def success_code(info: dict, keys: tuple[str, ...] = SUCCESS_KEYS) -> int:
    """`step_success` and which key said it, as one small int: -1 no flag, else 2 x the key's
    index in `keys` + the flag (so a worker's reply stays one int8 per step)."""
    for k, key in enumerate(keys):
        if key in info:
            return 2 * k + int(bool(info[key]))
    return -1


class Steps(NamedTuple):
    """One time step of the active envs of a batch, as evaluation reads it (not the envs' whole
    `info` dicts): entry j is batch row rows[j]. Plain arrays, so a worker's reply pickles fast."""

    rows: np.ndarray  # (k,) int: the batch rows stepped, ascending
    obs: np.ndarray  # (k, *observation shape)
    reward: np.ndarray  # (k,) float64
    terminated: np.ndarray  # (k,) bool
    truncated: np.ndarray  # (k,) bool
    success: np.ndarray  # (k,) int8: success_code(info): -1 the env has no flag, else key and flag
    restarted: np.ndarray  # (k,) bool: the episode ended and the env was reset for the row's next one
    first_obs: np.ndarray  # (k, *observation shape): that next episode's first observation (where restarted)
    fault: dict[int, str]  # batch row -> fault_of(info), for the rows whose step was a numerical fault

    def flag(self, j: int) -> bool | None:
        """Entry j's success flag (None: the env reports none)."""
        value = int(self.success[j])
        return None if value < 0 else bool(value & 1)

    def flag_key(self, j: int, keys: tuple[str, ...] = SUCCESS_KEYS) -> str | None:
        """The info key of entry j's success flag (None: the env reports none); `keys`: those the
        envs were stepped with (the pool's `success_keys`)."""
        value = int(self.success[j])
        return None if value < 0 else keys[value >> 1]


def step_envs(envs: Sequence[gym.Env], rows: np.ndarray, actions: np.ndarray, offset: int = 0,
              restarts: np.ndarray | None = None, keys: tuple[str, ...] = SUCCESS_KEYS) -> Steps:
    """Step envs[r] with actions[j] for each r = rows[j]; rows are reported as r + offset; `keys`:
    the info keys of the envs' success flag.

    `restarts[j]` >= 0: if this step ends row r's episode, reset its env at once with that seed
    (the row's next episode), so the next step needs no round trip of its own."""
    obs, reward, terminated, truncated, success, restarted, first, fault = [], [], [], [], [], [], [], {}
    for j, (r, action) in enumerate(zip(rows, actions, strict=True)):
        o, rew, term, trunc, info = envs[r].step(action)
        obs.append(o)
        reward.append(rew)
        terminated.append(term)
        truncated.append(trunc)
        success.append(success_code(info, keys))
        if (why := fault_of(info)) is not None:
            fault[int(r) + offset] = why
        again = bool((term or trunc) and restarts is not None and restarts[j] >= 0)
        restarted.append(again)
        first.append(envs[r].reset(seed=int(restarts[j]))[0] if again else o)
    return Steps(np.asarray(rows, dtype=np.int64) + offset, np.stack(obs), np.asarray(reward, dtype=np.float64),
                 np.asarray(terminated, dtype=bool), np.asarray(truncated, dtype=bool),
                 np.asarray(success, dtype=np.int8), np.asarray(restarted, dtype=bool), np.stack(first), fault)


def _join(parts: list[Steps]) -> Steps:
    if len(parts) == 1:
        return parts[0]
    return Steps(*(np.concatenate([getattr(p, f) for p in parts]) for f in Steps._fields[:-1]),
                 {r: why for p in parts for r, why in p.fault.items()})


class SerialPool:
    """`size` envs built and stepped in this process, one after another."""

    workers = 1

    def __init__(self, env_cfg: EnvConfig, size: int):
        self.env_cfg, self.size = env_cfg, size
        self.envs: list[gym.Env] = []
        try:
            for _ in range(size):
                self.envs.append(make_env(env_cfg, shaped=False))
        except BaseException:
            self.close()
            raise
        self.observation_space = self.envs[0].observation_space
        self.action_space = self.envs[0].action_space
        self.dt = env_dt(self.envs[0])
        self.success_keys = facts(env_cfg.id).success_keys  # read once the env's module is imported

    def reset(self, seeds: Sequence[int]) -> np.ndarray:
        """Reset env i with seeds[i] (the first len(seeds) envs); their observations, stacked."""
        return np.stack([env.reset(seed=s)[0] for env, s in zip(self.envs, seeds, strict=False)])

    def step(self, actions: np.ndarray, active: np.ndarray, restarts: np.ndarray | None = None) -> Steps:
        """Step env i with actions[i] for every row i where active[i] (at least one); a row whose
        episode ends is reset with restarts[i] where that is >= 0 (see `step_envs`)."""
        rows = np.flatnonzero(active)
        return step_envs(self.envs, rows, actions[rows], 0, None if restarts is None else restarts[rows],
                         self.success_keys)

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []

    def __enter__(self) -> SerialPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# ---- worker processes -------------------------------------------------------------------------

def _serve(conn, imports: list[str], parent: int) -> None:
    """A worker: answer ("build", (env_cfg, count)), ("reset", seeds), ("step", (rows, actions,
    offset)) and ("close", None) until told to close or the parent goes away."""
    # Ctrl-C and a hangup reach the whole group: the parent stops us (SIGTERM), and its death does too
    processes.serve_parent(parent)
    envs: list[gym.Env] = []
    keys = SUCCESS_KEYS
    try:
        adopt(imports)  # the parent's user modules, not the fork server's environment's
        while True:
            command, arg = conn.recv()
            if command == "step":
                rows, actions, offset, restarts = arg
                conn.send(("ok", step_envs(envs, rows, actions, offset, restarts, keys)))
            elif command == "reset":
                conn.send(("ok", [env.reset(seed=s)[0] for env, s in zip(envs, arg, strict=False)]))
            elif command == "build":  # new envs (the last pool's are closed first)
                _close_all(envs)
                env_cfg, count = arg
                for _ in range(count):
                    envs.append(make_env(env_cfg, shaped=False))
                keys = facts(env_cfg.id).success_keys
                conn.send(("ok", keys))
            else:
                break
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        pass  # the parent went away (or stopped us): nothing to report to
    except Exception as e:  # an env's own code may raise anything: report it in one line
        text = str(e) if isinstance(e, MotorlabError) else f"{type(e).__name__}: {e}"
        own = isinstance(e, MotorlabError) and not isinstance(e, UserCodeError)  # the env's own: name the worker
        try:
            conn.send(("error", (own, " ".join(text.split()))))
        except OSError:
            pass
    finally:
        _close_all(envs)
        conn.close()


def _close_all(envs: list[gym.Env]) -> None:
    while envs:
        try:
            envs.pop().close()
        except Exception:  # noqa: S110  closing what is left; an error was reported already
            pass


def _context():
    """Plain fork while this process runs a single thread, else forkserver (spawn where neither exists).

    A forked worker starts in milliseconds with everything this process has: its imports and
    MyoSuite's compiled models (a fresh process spends ~1.5 s importing MyoSuite and building its
    first hand twice, as much as 500 short zero-shot episodes take to step). Forking is unsafe
    when another thread may hold a lock at that moment (a study's steps run in threads, a progress
    bar refreshes in one), so then the workers come from the fork server instead, which imports
    this module (gymnasium, MuJoCo, motorlab's envs) once and forks clean children. Workers never
    run torch or render, so a parent's torch thread pool or EGL context is never used in them.
    """
    import threading

    if threading.active_count() == 1 and "fork" in mp.get_all_start_methods():
        return mp.get_context("fork")
    try:
        ctx = mp.get_context("forkserver")
    except ValueError:  # no forkserver (Windows)
        return mp.get_context("spawn")
    ctx.set_forkserver_preload([__name__])
    return ctx


def slices(size: int, workers: int) -> list[tuple[int, int]]:
    """Contiguous (start, stop) rows of `size` envs over `workers` processes, as even as can be."""
    base, extra = divmod(size, workers)
    bounds = np.cumsum([0] + [base + (k < extra) for k in range(workers)])
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


class ProcessPool:
    """`size` envs in `workers` processes, each holding a contiguous slice of them: this process
    the first slice, one child process each of the others.

    This process steps a slice of its own instead of waiting: on a 2-core machine, two child
    processes and an idle parent stepped the MyoSuite hand 1.3x faster than one process, this
    process and one child 1.8x (each step the children are sent their actions first, so their
    work overlaps this process's; a process woken from a blocking wait on this VM costs ~1 ms).

    A worker that raises gives one MotorlabError line; one that dies gives one too, with its exit
    code, never a hang (its pipe closes). Leaving the `with` block closes the workers (or, inside
    `keep_workers()`, keeps them for the next pool); on an exception (Ctrl-C included) they are
    terminated at once. Workers ignore SIGINT and SIGHUP themselves, so a Ctrl-C or a hangup is
    handled in one place, and a worker whose parent died gets SIGTERM from the kernel (Linux) or
    exits when its pipe closes (motorlab.processes.serve_parent).
    """

    def __init__(self, env_cfg: EnvConfig, size: int, workers: int):
        self.workers = max(2, min(workers, size))
        self._procs: list[Any] = []
        self._conns: list[Any] = []
        self._closed = False
        self._broken = False  # replies may be pending: close by terminating
        self._local: SerialPool | None = None
        ctx = _context()
        imports = imported_names()
        try:
            for k in range(1, self.workers):
                parent, child = ctx.Pipe()
                # not a daemon: a worker may start processes of its own (Upkie's second PyBullet env)
                proc = ctx.Process(target=_serve, args=(child, imports, os.getpid()), name=f"motorlab-env-{k}", daemon=False)
                proc.start()
                child.close()
                self._procs.append(proc)
                self._conns.append(parent)
            self.build(env_cfg, size)
        except BaseException:
            self.close(force=True)
            raise

    def build(self, env_cfg: EnvConfig, size: int) -> None:
        """Close the envs held, then build `size` envs of `env_cfg` over the same processes."""
        self._check_open()
        if size < self.workers:
            raise ValueError(f"{size} envs for {self.workers} processes")
        self.env_cfg, self.size = env_cfg, size
        self.slices = slices(size, self.workers)
        for k, (lo, hi) in enumerate(self.slices[1:], 1):
            self._send(k, ("build", (env_cfg, hi - lo)), "building its envs")
        if self._local is not None:
            self._local.close()
            self._local = None
        self._local = SerialPool(env_cfg, self.slices[0][1])  # while the children build theirs
        self.success_keys = self._local.success_keys
        for k in range(1, self.workers):
            keys = self._receive(k, "building its envs")
            if keys != self.success_keys:  # their flags' codes would be read with the wrong keys
                raise self._fail(k, f"reads the success flag from info{list(keys)}, this process from "
                                 f"info{list(self.success_keys)}: declare the env's facts with register_env "
                                 "in the module --import names, so every process declares them.")
        self.observation_space = self._local.observation_space
        self.action_space = self._local.action_space
        self.dt = self._local.dt

    def _fail(self, k: int, what: str) -> MotorlabError:
        self._broken = True
        lo, hi = self.slices[k]
        return MotorlabError(f"env worker {k + 1} of {self.workers} (envs {lo}-{hi - 1} of {self.env_cfg.id}) {what}")

    def _died(self, k: int, doing: str) -> MotorlabError:
        proc = self._procs[k - 1]
        proc.join(timeout=2)
        code = proc.exitcode
        how = f"killed by signal {-code}" if code is not None and code < 0 else f"exit code {code}"
        return self._fail(k, f"stopped unexpectedly while {doing} ({how}).")

    def _send(self, k: int, message: tuple, doing: str) -> None:
        try:
            self._conns[k - 1].send(message)
        except (BrokenPipeError, ConnectionResetError, EOFError, OSError):
            raise self._died(k, doing) from None

    def _receive(self, k: int, doing: str) -> Any:
        try:
            status, value = self._conns[k - 1].recv()
        except (EOFError, ConnectionResetError, OSError):
            raise self._died(k, doing) from None
        if status == "error":
            own, text = value
            if own:  # motorlab's own message (e.g. an unknown env id): as the serial path says it
                self._broken = True
                raise MotorlabError(text)
            raise self._fail(k, f"failed while {doing}: {text}")
        return value

    def _check_open(self) -> None:
        if self._closed or self._broken:
            raise MotorlabError("this env pool is closed (an env worker failed earlier).")

    def reset(self, seeds: Sequence[int]) -> np.ndarray:
        """Reset env i with seeds[i] (the first len(seeds) envs); their observations, stacked."""
        self._check_open()
        n = len(seeds)
        asked = []
        for k, (lo, hi) in enumerate(self.slices[1:], 1):
            if lo < n:
                self._send(k, ("reset", [int(s) for s in seeds[lo:min(hi, n)]]), "resetting")
                asked.append(k)
        here = self._local.reset(seeds[:self.slices[0][1]])
        return np.concatenate([here] + [np.stack(self._receive(k, "resetting")) for k in asked])

    def step(self, actions: np.ndarray, active: np.ndarray, restarts: np.ndarray | None = None) -> Steps:
        """Step env i with actions[i] for every row i where active[i] (at least one), resetting
        ended episodes with restarts[i] >= 0: send each worker its rows, step this process's slice,
        then receive from all."""
        self._check_open()
        asked = []
        for k, (lo, hi) in enumerate(self.slices[1:], 1):
            rows = np.flatnonzero(active[lo:hi])
            if rows.size:
                again = None if restarts is None else restarts[rows + lo]
                self._send(k, ("step", (rows, actions[rows + lo], lo, again)), "stepping")
                asked.append(k)
        mine = self.slices[0][1]
        here = ([self._local.step(actions[:mine], active[:mine], None if restarts is None else restarts[:mine])]
                if active[:mine].any() else [])
        return _join(here + [self._receive(k, "stepping") for k in asked])

    def close(self, force: bool = False) -> None:
        """Close the envs and stop the workers: ask them to, else (force, or a worker failed)
        terminate them. Inside `keep_workers()`, a pool closed without error keeps its workers."""
        if self._closed:
            return
        if self._local is not None:
            self._local.close()
            self._local = None
        kept = _keeper.get()
        if not (force or self._broken) and kept is not None:
            kept.append(self)
            return
        self._closed = True
        if not (force or self._broken):
            for conn in self._conns:
                try:
                    conn.send(("close", None))
                except OSError:
                    pass
            deadline = time.monotonic() + 5
            for proc in self._procs:
                proc.join(timeout=max(0.0, deadline - time.monotonic()))
        for proc in self._procs:
            if proc.is_alive():
                proc.terminate()
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()
                proc.join()
        for conn in self._conns:
            conn.close()

    def __enter__(self) -> ProcessPool:
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        self.close(force=exc_type is not None)

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            self.close(force=True)


EnvPool = SerialPool | ProcessPool

# pools whose workers wait for the next pool (keep_workers); per thread (a study runs steps in threads)
_keeper: contextvars.ContextVar[list[ProcessPool] | None] = contextvars.ContextVar("motorlab_kept_workers",
                                                                                   default=None)


@contextlib.contextmanager
def keep_workers():
    """Within this block a pool closed without error keeps its worker processes, and the next
    pool with as many processes builds its envs in them: several evaluations in a row (zero-shot
    on several envs) start processes once, and MyoSuite builds its first models (~1.3 s a
    process) once. The workers are stopped when the block ends (terminated on an exception)."""
    if _keeper.get() is not None:  # nested: the outer block keeps them
        yield
        return
    kept: list[ProcessPool] = []
    token = _keeper.set(kept)
    failed = True
    try:
        yield
        failed = False
    finally:
        _keeper.reset(token)
        for pool in kept:
            pool.close(force=failed)


def make_pool(env_cfg: EnvConfig, size: int, workers: int = 1) -> EnvPool:
    """`size` envs: in this process for workers <= 1, else over min(workers, size) processes
    (this one and children; inside `keep_workers()`, those of a pool closed before)."""
    if workers <= 1 or size <= 1:
        return SerialPool(env_cfg, size)
    wanted = max(2, min(workers, size))
    kept = _keeper.get() or []
    for pool in kept:
        if pool.workers == wanted:
            kept.remove(pool)
            try:
                pool.build(env_cfg, size)
            except BaseException:
                pool.close(force=True)
                raise
            return pool
    return ProcessPool(env_cfg, size, workers)


# ---- how many workers: all cores when it pays ------------------------------------------------

def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# When a second process pays, measured on a 2-core VM (this process and one child, a pool per
# evaluate call): the pendulum with PID (1000 steps of ~35 us an episode) 0.73x at 20 episodes
# (0.7 s of stepping), 1.3x from 50 (1.8 s) on; the MyoSuite hand, whose child process first
# imports MyoSuite and builds its model twice (~1.5 s before its ~60 ms builds), 0.54x at 10
# episodes, ~0.95x at 100 (3 s of stepping), 1.4x at 500 (15 s). So: every core once the
# estimated serial stepping exceeds CROSSOVER_S, which keeps a 10-episode evaluation (or a
# pendulum one of ~140 episodes) in this process.
CROSSOVER_S = 5.0
PROBE_STEPS = 30  # steps of a probe env timed to estimate that
DEFAULT_HORIZON = 1000  # episode length assumed for an env without a time limit


def auto_workers(env_cfg: EnvConfig, episodes: int, size: int) -> int:
    """Processes for `episodes` episodes, `size` envs at a time: all cores when it pays, else 1.

    The rule: estimate the serial env time as episodes x the time limit x the seconds of one
    step of a probe env (built here, timed over PROBE_STEPS random steps, then dropped); use
    every core when that exceeds CROSSOVER_S (see there). An episode that ends early makes it
    an overestimate, so a policy that fails fast may start workers it did not need. Examples on
    2 cores: 10 pendulum episodes (1000 steps of ~35 us: 0.35 s) stay in this process; 500
    episodes on the MyoSuite hand (50 steps of ~0.6 ms: 15 s) run on 2 processes.
    """
    cores = available_cores()
    if cores < 2 or size < 2:
        return 1
    probe = make_env(env_cfg, shaped=False)
    try:
        spec = probe.spec
        horizon = (spec.max_episode_steps if spec is not None else None) or DEFAULT_HORIZON
        probe.action_space.seed(0)
        probe.reset(seed=0)
        seconds = []
        for _ in range(PROBE_STEPS):
            action = probe.action_space.sample()
            start = time.perf_counter()
            _, _, terminated, truncated, _ = probe.step(action)
            seconds.append(time.perf_counter() - start)
            if terminated or truncated:
                probe.reset()
    finally:
        probe.close()
    # the median step: one step preempted by a busy machine would make a mean of 30 steps many times too long
    estimate = episodes * horizon * float(np.median(seconds))
    return min(cores, size) if estimate > CROSSOVER_S else 1
