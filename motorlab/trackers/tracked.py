"""Tracking runs to MLflow or W&B: the trackers a block of code tracks to, a background thread that talks to
them, a step kind's tracked run and the parents runs nest under (see motorlab.trackers)."""

from __future__ import annotations

import contextlib
import contextvars
import importlib
import queue
import sys
import threading
import time
from pathlib import Path
from typing import Any, Iterator

from motorlab.errors import MotorlabError, mask_secrets, redact
from motorlab.extras import require
from motorlab.trackers.targets import (
    BACKENDS,
    CLOSE_SECONDS,
    FLUSH_SECONDS,
    RunInfo,
    Target,
    parse,
    run_files,
)


def _module(backend: str):
    return importlib.import_module(f"motorlab.trackers.{backend}")


# The trackers runs started now go to, resolved, and the parent they nest under (its handoff:
# backends' run ids, name, root folder, W&B group). Context variables, not os.environ: a setting
# lasts for its `with` block, and a thread started with a copy of the context has its own.
_active: contextvars.ContextVar[tuple[Target, ...]] = contextvars.ContextVar("motorlab_trackers", default=())
_parent: contextvars.ContextVar[dict[str, Any] | None] = contextvars.ContextVar("motorlab_track_parent",
                                                                                 default=None)
_uris: set[str] = set()  # every tracker location used in this process: warnings never show its credentials


def check(values: list[str] | tuple[str, ...] | str | None) -> list[Target]:
    """The trackers `values` name, resolved, once each is usable: its package, a server that answers,
    a store that can be written (nothing given: none).

    Raises:
        MotorlabError: one line: an unknown tracker, a missing package (with the pip command), an
            unreachable server or an unwritable store.
    """
    resolved = []
    for t in parse(values):
        require(t.backend, t.backend, f"--track {t.backend} needs {_module(t.backend).LABEL}")
        resolved.append(_module(t.backend).check(t))
    return resolved


@contextlib.contextmanager
def _on(found: list[Target], parent: dict[str, Any] | None = None) -> Iterator[None]:
    """`found` on (and `parent` open, when given) for the block; what was before, after it."""
    _uris.update(t.where for t in found if t.where)
    tokens = [(_active, _active.set(tuple(found)))]
    if parent is not None:
        tokens.append((_parent, _parent.set(parent)))
    try:
        yield
    finally:
        for var, token in reversed(tokens):
            var.reset(token)


@contextlib.contextmanager
def tracking(values: list[str] | tuple[str, ...] | str | None) -> Iterator[list[Target]]:
    """Track the runs started inside the block (the CLI's --track, the API's track=; a script's
    `with motorlab.tracking("mlflow"):`), and nothing after it. Checks each tracker first (see
    `check`). Nothing given (None, []): nothing changes, an outer block's trackers stay on; given,
    they replace the outer block's for this block.

    Yields:
        The trackers in effect, resolved.

    Raises:
        MotorlabError: one line, before anything is written (see `check`).
    """
    found = check(values)
    if not found:
        yield targets()
        return
    with _on(found):
        yield found


@contextlib.contextmanager
def also(values: list[str] | tuple[str, ...] | str | None, where: str = "the target") -> Iterator[list[Target]]:
    """Track the block's runs to the trackers in effect and to `values` too: a sweep's or search's target's
    own --track, applied to its trials (and so to the sweep or search, the parent they nest under). Each is
    checked first (see `check`); one the block already tracks to, at the same place, is the same tracker.

    Yields:
        The trackers in effect.

    Raises:
        MotorlabError: one line: what `check` refuses, or a tracker named both in `where` and outside it
            with different places (two stores for one run).
    """
    found = check(values)
    current = {t.backend: t for t in targets()}
    for t in found:
        have = current.get(t.backend)
        if have is not None and have.where != t.where:
            raise MotorlabError(f"--track {mask_secrets(t.text())} in {where} and --track {mask_secrets(have.text())} given to "
                                f"it track one run to two places; give --track {t.backend} once.")
    new = [t for t in found if t.backend not in current]
    if not new:
        yield targets()
        return
    with _on([*current.values(), *new]):
        yield targets()


def targets() -> list[Target]:
    """The trackers runs started now go to (none outside a `tracking` or `adopted` block)."""
    return list(_active.get())


def handoff() -> dict[str, Any] | None:
    """What a process started now needs to track its runs as this one would, for its job settings
    (JSON): {"track": the trackers, resolved, "parent": the open parent's identity, when one is
    open}. None when tracking is off."""
    found = _active.get()
    if not found:
        return None
    out: dict[str, Any] = {"track": [t.text() for t in found]}
    if (parent := _parent.get()) is not None:
        out["parent"] = parent
    return out


@contextlib.contextmanager
def adopted(handoff: dict[str, Any] | None) -> Iterator[list[Target]]:
    """Track the runs of the block as the process that wrote `handoff` (see `handoff`) asked: its
    trackers, nested under its parent. Not checked again: the parent checked them, and a tracker
    that fails here warns once and the run goes on. None: nothing changes.

    Yields:
        The trackers in effect.
    """
    try:
        found = parse((handoff or {}).get("track") or [])
    except MotorlabError as e:  # a child process never fails over its tracking
        _warn_once("config", f"the tracking handed to this process is not used: {e}")
        found = []
    if not found:
        yield targets()
        return
    parent = handoff.get("parent")
    with _on(found, parent if isinstance(parent, dict) and parent else None):
        yield found


# ---- the background thread and the failures it reports -------------------------------------------

_warned: set[str] = set()
_broken: set[str] = set()  # backends switched off in this process after a failure
_lock = threading.Lock()


def _warn_once(key: str, message: str) -> None:
    # a tracker's error may quote its URI: its credentials are not shown (read here, in any thread)
    message = redact(message, *sorted(_uris))
    with _lock:
        if key in _warned:
            return
        _warned.add(key)
    sys.stderr.write(f"warning: {message}\n")
    sys.stderr.flush()


def _first_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0][:300]}" if text else type(e).__name__


class _Worker:
    """The one thread per process that talks to the trackers: tasks in order, and every
    FLUSH_SECONDS the scalars each open run has buffered."""

    def __init__(self) -> None:
        self.tasks: queue.Queue = queue.Queue()
        self.runs: list[_Run] = []
        self.thread = threading.Thread(target=self._loop, name="motorlab-tracking", daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while True:
            try:
                task = self.tasks.get(timeout=FLUSH_SECONDS)
            except queue.Empty:
                task = None
            try:
                for run in list(self.runs):
                    run.flush()
                if task is not None:
                    task()
            except BaseException as e:  # never let the thread die: later runs still need it
                _warn_once("worker", f"experiment tracking stopped working ({_first_line(e)}); runs go on untracked.")


_worker: _Worker | None = None


def _the_worker() -> _Worker:
    global _worker
    with _lock:
        if _worker is None or not _worker.thread.is_alive():  # none yet, or a forked child's copy
            _worker = _Worker()
        return _worker


class _Run:
    """One tracked run on each tracker, driven from the background thread."""

    def __init__(self, info: RunInfo, found: list[Target]):
        """`found`: the trackers, resolved and loaded (see `_load`)."""
        self.info = info
        self.sinks = [_module(t.backend).Sink(t) for t in found]
        self.buffer: list[tuple[str, float, int, float]] = []
        self.buffer_lock = threading.Lock()
        self.worker = _the_worker()
        self.live = False  # the trackers were told to start it (scalars are sent from then on)
        self.ended = False

    def _call(self, sink: Any, method: str, *args: Any) -> None:
        if sink.backend in _broken or (method != "start" and not sink.started):
            return
        try:
            getattr(sink, method)(*args)
        except Exception as e:  # a tracker's failure never stops a run
            _broken.add(sink.backend)
            _warn_once(sink.backend, f"tracking to {sink.label} failed ({_first_line(e)}); the run goes on and its "
                                     f"folder is complete, but {sink.label} gets nothing more from this process.")

    def submit(self, method: str, *args: Any) -> None:
        def task() -> None:
            for sink in self.sinks:
                self._call(sink, method, *args)

        self.worker.tasks.put(task)

    def start(self) -> None:
        def task() -> None:
            for sink in self.sinks:
                self._call(sink, "start", self.info)
            self.live = True

        self.worker.runs.append(self)
        self.worker.tasks.put(task)

    def scalar(self, tag: str, value: float, step: int) -> None:
        with self.buffer_lock:
            self.buffer.append((tag, value, step, time.time()))

    def flush(self) -> None:  # in the background thread
        if not self.live:
            return
        with self.buffer_lock:
            rows, self.buffer = self.buffer, []
        if rows:
            for sink in self.sinks:
                self._call(sink, "scalars", rows)

    def wait(self, seconds: float = CLOSE_SECONDS) -> bool:
        """Block until the thread has done everything asked of it so far (at most `seconds`)."""
        done = threading.Event()
        self.worker.tasks.put(done.set)
        if done.wait(seconds):
            return True
        _warn_once("timeout", f"the experiment tracker did not answer within {seconds:.0f} s; the run's folder is "
                              "complete, its tracked copy may not be.")
        return False

    def log_outputs(self, folder: Path | None, summary: dict[str, Any] | None) -> None:
        if summary:
            self.submit("summary", mask_secrets(summary))
        if folder is not None:
            self.submit("files", run_files(folder))

    def end(self, status: str) -> None:
        """FINISHED, FAILED or KILLED; waits for the trackers (bounded), then says where the run is."""
        if self.ended:
            return
        self.ended = True

        def task() -> None:
            self.flush()
            for sink in self.sinks:
                self._call(sink, "end", status)
            if self in self.worker.runs:
                self.worker.runs.remove(self)

        self.worker.tasks.put(task)
        if self.wait() and not self.info.nested:  # an outermost run: say where to look
            for sink in self.sinks:
                if sink.started and sink.backend not in _broken:
                    sys.stderr.write(f"tracked: {sink.where()}\n")

    def handoff(self) -> dict[str, Any]:
        return {s.backend: s.handoff() for s in self.sinks if s.started and s.backend not in _broken}


def _load(found: list[Target]) -> list[Target]:
    """The trackers resolved, their packages imported here, in the main thread, before a run starts:
    importing is the heavy part (seconds of Python holding the interpreter), and two threads must not
    import one package at once. Those that cannot be loaded (a handoff adopted where the package is
    missing) are left out, with a warning."""
    loaded = []
    for t in found:
        if t.backend in _broken:
            continue
        try:
            resolved = _module(t.backend).resolve(t)
            _module(t.backend).load(resolved)
            loaded.append(resolved)
        except Exception as e:
            _broken.add(t.backend)
            _warn_once(t.backend, f"cannot track to {_module(t.backend).LABEL} ({_first_line(e)}); runs go on "
                                  "untracked there.")
    return loaded


# ---- a step kind's run ---------------------------------------------------------------------------


def _info(kind: str, run_dir: Path | None, config: dict[str, Any], own_group: bool = False) -> RunInfo:
    parent = _parent.get() or {}
    name = kind if run_dir is None else Path(run_dir).name
    tags = {"motorlab.kind": kind}
    if run_dir is not None:
        run_dir = Path(run_dir).resolve()
        tags["motorlab.run_dir"] = str(run_dir)
        root = parent.get("root")  # the outermost parent's folder: names are unique inside it
        if root and run_dir.is_relative_to(root) and run_dir != Path(root):
            name = run_dir.relative_to(root).as_posix()
    if isinstance(config.get("seed"), int):
        tags["motorlab.seed"] = str(config["seed"])
    if parent.get("name"):
        tags["motorlab.parent"] = parent["name"]
    group = parent.get("group")
    if own_group and group is None:  # an outermost parent: every run under it shares its group
        group = f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"
    # what the trackers record (params, tags, names) holds no credential (a sweep target's --track URI)
    return RunInfo(name=mask_secrets(name), kind=kind, run_dir=run_dir, config=mask_secrets(config),
                   tags=mask_secrets(tags), parent={k: v for k, v in parent.items() if k in BACKENDS},
                   group=mask_secrets(group), nested=bool(parent))


class Step:
    """A step kind's run as a tracked run (see `step`)."""

    def __init__(self, kind: str, config: dict[str, Any], found: list[Target]):
        self.kind, self.config, self.found = kind, config, found
        self.run: _Run | None = None
        self.pending: list[tuple[str, float, int]] = []

    def folder_ready(self, run_dir: Path) -> None:
        if self.run is None:
            self.run = _Run(_info(self.kind, run_dir, self.config), self.found)
            self.run.start()
            for row in self.pending:
                self.run.scalar(*row)
            self.pending = []

    def scalar(self, tag: str, value: float, step: int) -> None:
        if self.run is None:
            self.pending.append((tag, value, step))
        else:
            self.run.scalar(tag, value, step)

    def done(self, run_dir: Path | None, summary: dict[str, Any]) -> None:
        """The run finished: its summary's numbers and its folder's files (the run ends when `step` does)."""
        if self.run is None:
            self.folder_ready(run_dir)
        self.run.log_outputs(run_dir, summary)


class _NoStep:
    """Tracking is off: nothing to do (and false, for `if tracked:`)."""

    def __bool__(self) -> bool:
        return False

    def folder_ready(self, run_dir: Path) -> None: ...

    def scalar(self, tag: str, value: float, step: int) -> None: ...

    def done(self, run_dir: Path | None, summary: dict[str, Any]) -> None: ...


_NO_STEP = _NoStep()
# The tracked step of this context: steps a study runs in threads (each in a copy of the context)
# are each their own tracked run, and a kind called inside another's run is part of the outer one.
_current: contextvars.ContextVar[Step | None] = contextvars.ContextVar("motorlab_tracked_step", default=None)


def _status(error: BaseException) -> str:
    return "KILLED" if isinstance(error, (KeyboardInterrupt, SystemExit)) else "FAILED"


@contextlib.contextmanager
def step(kind: str, settings: Any) -> Iterator[Step | _NoStep]:
    """Track one run of a step kind, when tracking is on (else nothing happens, at no cost).

    The tracked run starts at `folder_ready` (the run folder exists, the settings passed their
    checks), gets its scalars live, its summary and files at `done`, and ends with the block:
    FINISHED, or FAILED / KILLED when the block raised. A run inside another (a kind calling
    another kind) is part of the outer one."""
    found = targets() if _current.get() is None else []
    found = _load(found) if found else []  # before `run`, so its clock (wall_seconds) does not count the imports
    if not found:
        yield _NO_STEP
        return
    config = settings.config() if hasattr(settings, "config") else dict(settings)
    tracked = Step(kind, config, found)
    token = _current.set(tracked)
    try:
        yield tracked
    except BaseException as e:
        if tracked.run is not None:
            tracked.run.end(_status(e))
        raise
    else:
        if tracked.run is not None:
            tracked.run.end("FINISHED")
    finally:
        _current.reset(token)


def folder_ready(run_dir: Path) -> None:
    """The current step's run folder exists: its tracked run starts now (called by StepKind.start and train)."""
    if (current := _current.get()) is not None:
        current.folder_ready(run_dir)


def scalar(tag: str, value: Any, step: int | None) -> None:
    """One scalar of the current run, as TensorBoard would get it."""
    if (current := _current.get()) is not None:
        try:
            current.scalar(tag, float(value), int(step or 0))
        except (TypeError, ValueError):
            pass  # not a number: TensorBoard would have refused it too


def scalars(values: dict[str, Any], step: int) -> None:
    """Several scalars of the current run at one step (kinds that write no TensorBoard scalars)."""
    for tag, value in values.items():
        if value is not None:
            scalar(tag, value, step)


def mirror(writer: Any) -> Any:
    """A TensorBoard SummaryWriter whose scalars also go to the current tracked run (the same
    writer, its add_scalar wrapped; unchanged when no run is tracked)."""
    if _current.get() is None or getattr(writer, "_motorlab_tracked", False):
        return writer
    add_scalar = writer.add_scalar

    def tracked_add_scalar(tag, scalar_value, global_step=None, *args, **kwargs):
        result = add_scalar(tag, scalar_value, global_step, *args, **kwargs)
        scalar(tag, scalar_value, global_step)
        return result

    writer.add_scalar = tracked_add_scalar
    writer._motorlab_tracked = True
    return writer


# ---- sweeps, studies, tune: parents ---------------------------------------------------------------


class Parent:
    """A sweep, study or tune folder as a tracked run that the runs started under it nest under."""

    def __init__(self, run: _Run | None):
        self.run = run

    def outputs(self, folder: Path, summary: dict[str, Any] | None) -> None:
        if self.run is not None:
            self.run.log_outputs(folder, summary)


_parents: dict[str, Parent] = {}  # open parents by folder


@contextlib.contextmanager
def parent(kind: str, folder: Path, config: dict[str, Any]) -> Iterator[Parent]:
    """Track a sweep, study or tune in `folder` as a parent run (when tracking is on). Runs started
    inside the block, here or in processes given `handoff()` here, nest under it; `outputs` (or
    motorlab.trackers.outputs) logs its summary and files. Ends FINISHED, or FAILED/KILLED."""
    found = targets()
    found = _load(found) if found else []
    if not found:
        yield Parent(None)
        return
    folder = Path(folder).resolve()
    run = _Run(_info(kind, folder, config, own_group=True), found)
    run.start()
    run.wait()  # the children need its identity
    identity = {**run.handoff(), "name": run.info.name, "root": (_parent.get() or {}).get("root") or str(folder)}
    if run.info.group:
        identity["group"] = run.info.group
    token = _parent.set(identity)
    tracked = _parents[str(folder)] = Parent(run)
    try:
        yield tracked
    except BaseException as e:
        run.end(_status(e))
        raise
    else:
        run.end("FINISHED")
    finally:
        _parents.pop(str(folder), None)
        _parent.reset(token)


def outputs(folder: Path, summary: dict[str, Any] | None) -> None:
    """Log a sweep's, study's or tune's summary and files to its open parent run (no parent open
    for `folder`, e.g. a search run from Python: nothing)."""
    tracked = _parents.get(str(Path(folder).resolve()))
    if tracked is not None:
        tracked.outputs(folder, summary)
