"""One env in its own process, behind the ordinary `gym.Env` interface.

Some simulators keep global state: Upkie's PyBullet backend talks to PyBullet's
default client, so a process can hold only one Upkie env (a second one in the same
process breaks the first). Evaluation steps several envs side by side, so each env
beyond the first runs in a child process through this proxy.

Gymnasium's AsyncVectorEnv also runs envs in processes, but it batches spaces and
infos and resets automatically; a one-env proxy keeps every motorlab wrapper
(delay, history, reward shaping, evaluation) unchanged, which is why it is written here.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym

from motorlab import processes
from motorlab.errors import MotorlabError


def _serve(conn, factory: Callable[[], gym.Env], parent: int | None = None) -> None:
    """Child process: build the env, then answer (method, args, kwargs) requests; it stops with the
    process it serves (motorlab.processes.serve_parent: a fork server's child is no child of that process)."""
    if parent is not None:
        processes.serve_parent(parent)
    try:
        env = factory()
        conn.send(("ok", (env.observation_space, env.action_space, env.spec, env.metadata, env.render_mode,
                          getattr(env.unwrapped, "dt", None))))
    except BaseException as e:  # report why the env could not be built, then stop
        conn.send(("error", _portable(e)))
        return
    try:
        while True:
            method, args, kwargs = conn.recv()
            if method == "close":
                env.close()
                conn.send(("ok", None))
                return
            try:
                conn.send(("ok", getattr(env, method)(*args, **kwargs)))
            except Exception as e:
                conn.send(("error", _portable(e)))
    except (EOFError, KeyboardInterrupt):  # the parent went away or was interrupted
        env.close()


def _portable(e: BaseException) -> Exception:
    """The exception itself where it pickles as a MotorlabError, else its text with the child's traceback."""
    if isinstance(e, MotorlabError):
        return e
    return RuntimeError(f"{type(e).__name__}: {e}\n(in the env process)\n{traceback.format_exc()}")


class ProcessEnv(gym.Env):
    """`factory()` built and stepped in a child process, forked by a fork server: one clean
    single-threaded process (safe next to torch threads, as "spawn" is) started at the first
    ProcessEnv with the simulator already imported, which forks each child in milliseconds. With
    "spawn" every child imported Python, motorlab and the simulator again (~1.5 s per Upkie env).

    Args:
        factory: a picklable callable returning the env (e.g. a functools.partial of a
            module-level function).
        preload: modules the fork server imports once (the simulator's); those that fail to
            import are skipped. The first ProcessEnv of a process starts the server, so its
            list is the one that counts.
    """

    def __init__(self, factory: Callable[[], gym.Env], preload: Sequence[str] = ()):
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(child, factory, os.getpid()), daemon=True)
        self._proc.start()
        child.close()
        self._closed = False
        (self.observation_space, self.action_space, self.spec, self.metadata, self.render_mode,
         self.dt) = self._answer()

    def _answer(self) -> Any:
        try:
            status, value = self._conn.recv()
        except EOFError:
            self._closed = True
            raise MotorlabError(f"the env process stopped unexpectedly (exit code {self._proc.exitcode}).") from None
        if status == "error":
            raise value
        return value

    def _call(self, method: str, *args, **kwargs) -> Any:
        if self._closed:
            raise MotorlabError("this env is closed.")
        self._conn.send((method, args, kwargs))
        return self._answer()

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        return self._call("reset", seed=seed, options=options)

    def step(self, action):
        return self._call("step", action)

    def render(self):
        return self._call("render")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._conn.send(("close", (), {}))
            self._conn.recv()
        except (EOFError, OSError, BrokenPipeError):
            pass
        self._proc.join(timeout=5)
        if self._proc.is_alive():
            self._proc.terminate()
        self._conn.close()

    def __del__(self):
        if not getattr(self, "_closed", True):
            self.close()
