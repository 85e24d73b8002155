"""Which folders are motorlab's to write: a run folder carries proof, and has one writer at a time.

- **The marker** (`.motorlab-run`, JSON): every folder motorlab makes for a run says so, with the kind
  of run it holds, the process that wrote it and, once that process is done with it, the entries it
  left there. `--overwrite` and `--resume` act only on a folder whose marker names their own kind;
  motorlab writes into no other non-empty folder (motorlab.runs decides, this module only reads and
  writes the proof).
- **The lock**: an exclusive `flock` on the run folder itself, taken before anything is written and
  held until the run is done (`lock_scope`). The kernel drops it when its process dies, however it
  dies, so a lock is never stale: a folder whose writer was killed is free at once. A lock on the
  folder's own inode, not a lock file beside it, leaves nothing in the user's directories, and moves
  with the folder when --overwrite moves a run aside.
- **No links**: a symbolic link planted inside a run folder would make later writes land outside
  --out; motorlab refuses to write into a run folder that holds one.

fcntl, not the `filelock` package: filelock locks a file (one more file in every run folder, left
behind), while a directory's own flock needs no file and three calls.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import tempfile
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

from motorlab.errors import MotorlabError

MARKER = ".motorlab-run"
SUMMARY = "summary.json"


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~current_umask()  # what open() gives; mkstemp's 0600 would hide plots and videos from others


@contextlib.contextmanager
def atomic_path(path: Path, suffix: str = ".tmp"):
    """A temp file beside `path` to write to (by name, e.g. for ffmpeg); renamed over `path` when
    the block ends, removed if it fails. It gets the permissions open() would give, not mkstemp's 0600.
    The rename replaces a link at `path` itself, never the file it points to."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name[:200]}.", suffix=suffix)
    os.fchmod(fd, _FILE_MODE)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to a temp file beside `path`, fsync, then rename over it."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def is_complete(run_dir: Path) -> bool:
    """True when `run_dir` holds a finished run: a summary.json that parses as a JSON object (a
    damaged one, e.g. cut short by a full disk, is an unfinished run)."""
    try:
        return isinstance(json.loads((Path(run_dir) / SUMMARY).read_bytes()), dict)
    except (OSError, ValueError):
        return False


@dataclass(frozen=True)
class Claim:
    """What a run folder's marker says of it."""

    kind: str  # the kind of run it holds: a step kind's name, "study", "sweep", "tune", "export"
    pid: int | None  # the process that last took it
    files: tuple[str, ...] | None  # what it held when that process was done, as `contents` (None: not known yet)


def read_claim(run_dir: Path) -> Claim | None:
    """The marker of `run_dir` (None: it has none).

    Raises:
        MotorlabError: a marker that is not motorlab's JSON (a damaged or hand-made one), or a link.
    """
    path = Path(run_dir) / MARKER
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:
        return None
    except OSError as e:
        raise MotorlabError(f"{path} cannot be read ({os.strerror(e.errno or 0).lower()}); it is not a motorlab run "
                            "folder's marker: choose another --out.") from None
    with os.fdopen(fd, "rb") as f:
        data = f.read()
    try:
        raw = json.loads(data)
        files = raw.get("files")
        return Claim(kind=str(raw["kind"]), pid=raw.get("pid"),
                     files=tuple(str(f) for f in files) if isinstance(files, list) else None)
    except (ValueError, KeyError, TypeError, AttributeError):
        raise MotorlabError(f"{path} is damaged (not the marker motorlab writes); motorlab will not write into "
                            f"{run_dir}: choose another --out.") from None


def write_claim(run_dir: Path, claim: Claim) -> None:
    """The marker, written whole (temp file, then rename: a kill leaves the old one or the new one)."""
    data = {"motorlab": 1, "kind": claim.kind, "pid": claim.pid,
            "files": list(claim.files) if claim.files is not None else None}
    atomic_write_text(Path(run_dir) / MARKER, json.dumps(data) + "\n")


def mark(run_dir: Path, kind: str) -> None:
    """Make `run_dir` a run folder of `kind`. A marker that says so already is left as it is (a resumed
    run's folder changes only where the run writes)."""
    old = read_claim(run_dir)
    if old is None or old.kind != kind:
        write_claim(run_dir, Claim(kind, os.getpid(), None))


_MARKER_TEMP = f".{MARKER}."  # the marker's temp file while it is written (`atomic_path`'s prefix)


def _is_marker(name: str) -> bool:
    """The marker, or its temp file: another process marking a folder it just made shows it for a moment,
    and the folder is no less empty for it."""
    return name == MARKER or name.startswith(_MARKER_TEMP)


def entries(run_dir: Path) -> set[str]:
    """The names in `run_dir`, the marker aside."""
    return {e.name for e in os.scandir(run_dir) if not _is_marker(e.name)}


def contents(run_dir: Path) -> set[str]:
    """Everything under `run_dir` as paths relative to it (`plots/curve.png`, `plots`), the marker aside: what
    a finished run's marker lists, and what an --overwrite compares with it. A run folder inside it (a
    study's step, a sweep's trial: its own marker) is one entry, not looked into: it lists its own."""
    found: set[str] = set()

    def walk(folder: str, prefix: str) -> None:
        with os.scandir(folder) as listing:
            for entry in listing:
                if not prefix and _is_marker(entry.name):
                    continue
                found.add(prefix + entry.name)
                if entry.is_dir(follow_symlinks=False) and not os.path.lexists(os.path.join(entry.path, MARKER)):
                    walk(entry.path, f"{prefix}{entry.name}/")

    walk(os.fspath(run_dir), "")
    return found


# ---- one writer at a time -------------------------------------------------------------------

@dataclass
class _Held:
    fd: int
    path: Path
    count: int


_HELD: dict[tuple[int, int], _Held] = {}  # this process's locks, by the folder's (device, inode)
_SCOPE: ContextVar[list[tuple[int, int]] | None] = ContextVar("motorlab_lock_scope", default=None)


def lock(run_dir: Path) -> None:
    """Take `run_dir`'s lock for this process, until the innermost `lock_scope` ends (or the process does).
    Taken again by the same process (a study's step, a kind called inside another), it is the same lock.

    Raises:
        MotorlabError: another process holds it (named by its pid, where its marker says).
    """
    fd = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY)
    st = os.fstat(fd)
    key = (st.st_dev, st.st_ino)
    scope = _SCOPE.get()
    if key in _HELD:
        os.close(fd)
        _HELD[key].count += 1
    else:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise MotorlabError(busy_message(run_dir)) from None
        _HELD[key] = _Held(fd, Path(run_dir), 1)
    if scope is not None:
        scope.append(key)


def busy_message(run_dir: Path) -> str:
    """The one line refusing a second writer, naming the holder's pid (the kernel's list of locks says
    who holds it; the marker's writer where that list cannot be read)."""
    pid = _lock_holder(run_dir)
    if pid is None:
        try:
            claim = read_claim(run_dir)
        except MotorlabError:
            claim = None
        pid = claim.pid if claim is not None else None
    holder = f"pid {pid}" if pid else "its pid unknown"
    return (f"{run_dir} is being written by another motorlab process ({holder}); wait for it to end, or choose "
            "another --out.")


def _lock_holder(run_dir: Path) -> int | None:
    """The pid /proc/locks gives for the flock on `run_dir` (Linux; None elsewhere or when none is held)."""
    try:
        st = os.stat(run_dir)
        with open("/proc/locks") as f:
            lines = f.read().splitlines()
    except OSError:
        return None
    where = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    for line in lines:
        cells = line.split()
        if len(cells) > 5 and cells[1] == "FLOCK" and cells[5] == where and cells[4].isdigit():
            return int(cells[4])
    return None


def holds(run_dir: Path) -> bool:
    """True when this process holds `run_dir`'s lock."""
    try:
        st = os.stat(run_dir)
    except OSError:
        return False
    return (st.st_dev, st.st_ino) in _HELD


def free(run_dir: Path) -> bool:
    """True when no other process holds `run_dir`'s lock (a quick try, given back at once)."""
    if holds(run_dir):
        return True
    try:
        fd = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False
    finally:
        os.close(fd)  # closing gives the lock back


@contextlib.contextmanager
def lock_scope():
    """The run-folder locks taken inside the block are given back when it ends (a run that finished
    records its entries in its marker first: what a later --overwrite may delete with it)."""
    taken: list[tuple[int, int]] = []
    token = _SCOPE.set(taken)
    try:
        yield
    finally:
        _SCOPE.reset(token)
        for key in reversed(taken):
            _release(key)


def _release(key: tuple[int, int]) -> None:
    held = _HELD.get(key)
    if held is None:
        return
    held.count -= 1
    if held.count > 0:
        return
    try:
        st = os.stat(held.path)
        if (st.st_dev, st.st_ino) == key:  # still where it was taken (not a run moved aside)
            record_entries(held.path)
    except OSError:
        pass  # gone, or unreadable: the marker keeps what it said
    finally:
        del _HELD[key]
        os.close(held.fd)


def record_entries(run_dir: Path) -> None:
    """A finished run's marker names what it holds; an unfinished run's stays unknown (and a folder
    with no marker gets none: it is not a run folder)."""
    claim = read_claim(run_dir)
    if claim is not None and is_complete(run_dir):
        write_claim(run_dir, Claim(claim.kind, claim.pid, tuple(sorted(contents(run_dir)))))


# ---- writes never leave the folder ------------------------------------------------------------

def refuse_links(run_dir: Path) -> None:
    """Refuse a run folder that holds a symbolic link anywhere inside (a write through it would land
    outside --out). `run_dir` itself may be a link: the user named it.

    Raises:
        MotorlabError: naming the first link.
    """
    for root, dirs, files in os.walk(run_dir, followlinks=False):
        for name in dirs + files:
            path = Path(root) / name
            if path.is_symlink():
                raise MotorlabError(f"{path} is a symbolic link; motorlab never writes through links in a run "
                                    f"folder (it would write outside {run_dir}): remove it, or choose another --out.")
