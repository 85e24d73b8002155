"""How motorlab's processes stop, and that none outlives the command that started it.

SIGINT (Ctrl-C), SIGTERM (what `timeout`, `kill`, Slurm and Ray send) and SIGHUP (a closed
terminal) stop a command alike: inside `stopped_by_signals()` each raises KeyboardInterrupt
where Python next checks for signals, so the cleanup Ctrl-C always had runs for all three
(training processes asked to stop, so their checkpoints are kept and `--resume` goes on; an
`--overwrite`'s old folder put back). The command then exits with 128 + the signal's number,
as a shell reports a process the signal ended: 130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP.

A process that a signal cannot reach in time (SIGKILL, the OOM killer) cannot clean up, but
its children must not train on: every child motorlab starts asks the kernel for SIGTERM when
its parent dies (`die_with_parent`, Linux's PR_SET_PDEATHSIG), which stops it as above.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from types import FrameType

STOP_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
PARENT_VAR = "MOTORLAB_PARENT_PID"  # set by the launcher for `python -m motorlab.worker`: who must outlive it
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


@dataclass
class Stop:
    """What stopped the block: the last stop signal received (SIGINT when none was: a
    KeyboardInterrupt raised by other means, e.g. Click's Abort)."""

    signum: int = signal.SIGINT
    stopping: bool = False  # a stop signal arrived: the cleanup's deadline runs

    @property
    def status(self) -> int:
        """The exit status a shell shows for a process this signal ended: 128 + its number."""
        return 128 + self.signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


@contextlib.contextmanager
def stopped_by_signals(take: Iterable[int] = (), grace: float = 60.0) -> Iterator[Stop]:
    """Inside the block, every stop signal raises KeyboardInterrupt in the main thread; the handlers
    before it are restored after. A signal ignored on entry stays ignored (`nohup` ignores SIGHUP
    on purpose; a shell starts background jobs with SIGINT ignored), unless it is in `take`: the
    signals this process's parent stops it with (a worker's SIGINT and SIGTERM). Outside the main
    thread (where Python cannot set handlers) the block changes nothing.

    `grace`: seconds the cleanup may take after the first stop signal before the process is
    ended regardless. KeyboardInterrupt lands wherever the main thread is, also inside a library's
    critical section (TensorBoard's event writer was seen to hang in its close after one), and a
    process whose parent died has nobody left to kill it: it must not live on, hung."""
    stop = Stop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def interrupt(signum: int, frame: FrameType | None) -> None:
        if not stop.stopping:
            stop.stopping = True
            _deadline(grace)
        stop.signum = signum
        raise KeyboardInterrupt

    unblock()
    taken = set(take)
    before = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for s, handler in before.items():
        if handler is not signal.SIG_IGN or s in taken:
            signal.signal(s, interrupt)
    try:
        yield stop
    finally:
        for s, handler in before.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)


def _deadline(seconds: float) -> None:
    """End this process `seconds` from now unless it has exited (SIGALRM from the kernel: no lock, no
    thread, nothing the interrupted code may hold; the timer is never cancelled, as the process is
    on its way out)."""
    if hasattr(signal, "setitimer"):
        import faulthandler

        # where it hung, on stderr, just before the end: a cleanup that never finishes says where it waits
        faulthandler.dump_traceback_later(max(seconds - 1.0, seconds / 2), exit=False)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.setitimer(signal.ITIMER_REAL, seconds)


def unblock() -> None:
    """Unblock the stop signals: Ray's workers block SIGINT, and a process they start inherits the
    mask, so a trial would never see the signal that stops it early, only the kill after it."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, set(STOP_SIGNALS))


def die_with_parent(parent: int | None = None) -> None:
    """Ask the kernel to send this process SIGTERM when its parent dies (Linux; elsewhere nothing).

    `parent`: the pid of the process that started this one (on purpose or through a fork server);
    if it died before the request was made, this process is sent SIGTERM now, as it would have been.
    """
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
            return
    except (OSError, AttributeError):  # no libc prctl (an odd platform): nothing to ask for
        return
    if parent is not None and os.getppid() != parent and not _alive(parent):
        os.kill(os.getpid(), signal.SIGTERM)


def die_with_launcher() -> None:
    """`die_with_parent` for a process the launcher started (it names itself in $MOTORLAB_PARENT_PID);
    a process started by hand, without it, is left alone."""
    parent = os.environ.get(PARENT_VAR, "")
    if parent.isdigit():
        die_with_parent(int(parent))


def child_env() -> dict[str, str]:
    """The variables that make a child started with them `die_with_launcher` of this process."""
    return {PARENT_VAR: str(os.getpid())}


def serve_parent(parent: int) -> None:
    """Signals of a worker process its parent stops (env and collection workers): SIGINT and SIGHUP,
    which a terminal sends the whole process group, are ignored (the parent stops its workers when
    it stops); SIGTERM (the parent's `terminate()`, or its death) ends the worker at once."""
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_DFL if s == signal.SIGTERM else signal.SIG_IGN)
    die_with_parent(parent)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists, owned by another user
        return True
    return True


def in_processes(calls: Iterable, workers: int | None = None) -> list:
    """joblib's `Parallel(backend="loky")` over `calls` (each a `delayed(f)(...)`), with its worker
    processes shut down before returning: loky keeps a pool alive for reuse, which would outlive
    the call (and a later evaluation pool would find someone else's children)."""
    from joblib import Parallel
    from joblib.externals.loky import reusable_executor

    try:
        return Parallel(n_jobs=workers or -1, backend="loky")(calls)
    finally:
        pool = reusable_executor._executor  # the one loky kept, if this call started one (1 worker starts none)
        if pool is not None:
            pool.shutdown(wait=True)
