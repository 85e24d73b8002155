"""Fresh `python -m motorlab` processes for the tests, forked from a process that has already imported the
libraries every command imports (tests/helpers.py run_cli).

Why: a command that trains spends ~2.5 s of CPU importing torch, Stable-Baselines3, Gymnasium, MuJoCo and
motorlab before it does anything, and ~1 s tearing them down at exit; make test starts ~200 of them.
Measured 2026-11-30 (a make test run with every interpreter's CPU time logged): 537 interpreters used 950
of the suite's 1,650 CPU seconds, the tests' ~200 commands 640 of them; forked from here, the same
commands used 326. A fork of a process that has imported them and done nothing else is the
process a fresh start would be after those imports: its own pid, exit status, working directory,
environment, argv, descriptors 0-2 and fresh random seeds. What it cannot be is a process whose imports
saw a different environment, so a command whose environment differs from the zygote's in a variable
read at import (IMPORT_SENSITIVE) runs in a real fresh interpreter (run_cli's fallback), as does any
test that passes fresh=True.

Protocol (one Unix socket; one connection a command, so commands from several threads run side by side):
the client sends one JSON line {argv, cwd, env} with its stdout and stderr files' descriptors
(SCM_RIGHTS); the zygote forks a waiter, which forks the command and answers {"pid": N}, then, when the
command has ended, {"code": exit status as subprocess reports it (-N: killed by signal N)}.
"""

from __future__ import annotations

import atexit
import importlib
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

# what a command imports on every path that trains, plans or plots (motorlab's own modules read no
# environment variable at import: they read them when a command runs)
PRELOAD = ("numpy", "torch", "gymnasium", "mujoco", "stable_baselines3", "matplotlib", "matplotlib.pyplot",
           "motorlab.cli")
# variables the libraries above read at import: a command whose value differs from the zygote's is not
# the process a fresh interpreter would be, so it runs in one (PYTHONPATH is handled apart: see _sys_path)
IMPORT_SENSITIVE = re.compile(r"PYTHON(?!PATH$)\w*|MUJOCO_\w+|PYOPENGL_PLATFORM|MPL\w*|OMP_\w+|MKL_\w+|"
                              r"OPENBLAS_\w+|KMP_\w+|TORCH_\w*|CUDA_\w+|LD_\w+|HOME|XDG_\w+|TMPDIR|LANG|LC_\w+")


def _sensitive(env: dict[str, str]) -> dict[str, str]:
    return {k: v for k, v in env.items() if IMPORT_SENSITIVE.fullmatch(k)}


def _entries(pythonpath: str | None) -> list[str]:
    return [os.path.abspath(p) for p in (pythonpath or "").split(os.pathsep) if p]


# ---- the zygote (python -m tests.zygote SOCKET) --------------------------------------------------------


def _sys_path(base: list[str], cwd: str, pythonpath: str | None) -> list[str]:
    """sys.path as `python -m` starts it in `cwd` with this PYTHONPATH: the working directory, then
    PYTHONPATH's entries, then the interpreter's own (`base`: the zygote's, less its first)."""
    return [cwd, *_entries(pythonpath), *base]


def _become(request: dict, out: int, err: int, base_path: list[str]) -> None:
    """In the forked command: its descriptors, directory, environment, argv and seeds; then motorlab's
    __main__, and the end a fresh interpreter would give it: its exit status, threads joined, atexit
    handlers run, output flushed."""
    import random
    import runpy

    import numpy as np

    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(out, 1)
    os.dup2(err, 2)
    for fd in (null, out, err):
        os.close(fd)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    sys.path[:] = _sys_path(base_path, request["cwd"], request["env"].get("PYTHONPATH"))
    random.seed()
    np.random.seed()
    sys.argv = ["-m", *request["argv"]]
    interrupted = False
    try:
        runpy.run_module("motorlab", run_name="__main__", alter_sys=True)
        code = 0
    except SystemExit as e:  # as the interpreter reads it
        code = e.code if isinstance(e.code, int) else 0 if e.code is None else 1
        if not isinstance(e.code, int | None):
            print(e.code, file=sys.stderr)
    except BaseException as e:  # noqa: B036 - an uncaught exception: its traceback, exit status 1
        sys.excepthook(type(e), e, e.__traceback__)
        code, interrupted = 1, isinstance(e, KeyboardInterrupt)
    # What the interpreter's exit does that anyone can see (join threads, atexit, flush), but not the
    # teardown of every module, which takes ~1 s once torch is imported
    threading._shutdown()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    if interrupted:  # Python ends on an uncaught Ctrl-C by SIGINT itself
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)
    os._exit(code & 0xFF)


def _wait_for_command(conn: socket.socket, base_path: list[str]) -> None:
    """The waiter: fork the command (which never returns: _become ends it), say its pid, wait for it,
    say its exit status, and leave."""
    try:
        data, fds, _, _ = socket.recv_fds(conn, 1 << 20, 2)
        while not data.endswith(b"\n"):
            data += conn.recv(1 << 20)
        request = json.loads(data.decode())
        pid = os.fork()
    except BaseException:  # noqa: B036 - a waiter must never return to the server's loop
        os._exit(1)
    if pid == 0:
        conn.close()
        _become(request, fds[0], fds[1], base_path)
    try:
        for fd in fds:
            os.close(fd)
        conn.sendall(json.dumps({"pid": pid}).encode() + b"\n")
        _, status = os.waitpid(pid, 0)
        conn.sendall(json.dumps({"code": os.waitstatus_to_exitcode(status)}).encode() + b"\n")
    finally:
        os._exit(0)


def serve(path: str) -> None:
    for name in PRELOAD:
        importlib.import_module(name)
    base_path = sys.path[1:]  # started without PYTHONPATH: the interpreter's own entries
    parent = os.getppid()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(16)
    server.settimeout(1.0)
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    while os.getppid() == parent:  # the pytest process that started it is alive
        while True:  # reap the waiters
            try:
                if os.waitpid(-1, os.WNOHANG)[0] == 0:
                    break
            except ChildProcessError:
                break
        try:
            conn, _ = server.accept()
        except TimeoutError:
            continue
        conn.settimeout(None)
        if os.fork() == 0:
            server.close()
            _wait_for_command(conn, base_path)
        conn.close()


# ---- the client (in the pytest process) ---------------------------------------------------------------


class Zygote:
    def __init__(self, env: dict[str, str]) -> None:
        # no PYTHONPATH: each command gets its own in front of the interpreter's entries (_sys_path)
        self.env = {k: v for k, v in env.items() if k != "PYTHONPATH"}
        self.folder = tempfile.mkdtemp(prefix="motorlab-zygote-")
        self.socket = os.path.join(self.folder, "socket")
        root = str(Path(__file__).resolve().parent.parent)
        self.process = subprocess.Popen([sys.executable, "-m", "tests.zygote", self.socket], cwd=root, env=self.env,
                                        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE)
        line = self.process.stdout.readline()
        if line != b"ready\n":
            raise RuntimeError(f"the tests' zygote did not start (it said {line!r})")
        atexit.register(self.close)

    def serves(self, env: dict[str, str]) -> bool:
        """Whether a command with this environment is the process a fresh interpreter would be."""
        return self.process.poll() is None and _sensitive(env) == _sensitive(self.env)

    def run(self, argv: list[str], cwd: str, env: dict[str, str], timeout: float | None,
            cmd: list[str]) -> subprocess.CompletedProcess:
        with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err, \
                socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as conn:
            conn.connect(self.socket)
            request = json.dumps({"argv": argv, "cwd": cwd, "env": env}).encode() + b"\n"
            socket.send_fds(conn, [request], [out.fileno(), err.fileno()])
            answers = _Lines(conn)
            pid = json.loads(answers.next())["pid"]
            conn.settimeout(timeout)
            try:
                line = answers.next()
            except TimeoutError:
                os.kill(pid, signal.SIGKILL)
                conn.settimeout(None)
                answers.next()  # the waiter has reaped it
                raise subprocess.TimeoutExpired(cmd, timeout, _text(out), _text(err)) from None
            code = json.loads(line)["code"]
            return subprocess.CompletedProcess(cmd, code, _text(out), _text(err))

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        shutil.rmtree(self.folder, ignore_errors=True)


class _Lines:
    """The waiter's answers, a line at a time (a socket file cannot be read again after a timeout)."""

    def __init__(self, conn: socket.socket) -> None:
        self.conn, self.buffer = conn, b""

    def next(self) -> bytes:
        while b"\n" not in self.buffer:
            chunk = self.conn.recv(4096)
            if not chunk:
                raise RuntimeError("the tests' zygote closed the connection before the command's answer")
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        return line


def _text(f) -> str:
    """What subprocess.run(text=True) returns: the locale's decoding, universal newlines."""
    import locale

    f.seek(0)
    data = f.read().decode(locale.getpreferredencoding(False))
    return data.replace("\r\n", "\n").replace("\r", "\n")


_lock = threading.Lock()
_zygotes: dict[int, Zygote] = {}


def zygote_for(env: dict[str, str]) -> Zygote | None:
    """This process's zygote (started with the first command's environment), or None where it cannot
    give this environment the process a fresh interpreter would (run the command in one)."""
    with _lock:
        z = _zygotes.get(os.getpid())
        if z is None:
            z = _zygotes[os.getpid()] = Zygote(env)
    return z if z.serves(env) else None


if __name__ == "__main__":
    serve(sys.argv[1])
