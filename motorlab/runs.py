"""Run folders: one per step, written so that nothing is ever half-written, and never lost.

A run folder holds `config.toml` (resolved settings), `summary.json` (headline
numbers, flat keys), `metrics.csv`, `tensorboard/`, artifacts, `plots/`.
`summary.json` is written last: a folder without a summary.json that parses is an unfinished run.

A folder that holds a finished run is never written into by accident: a new run there is
refused unless the command runs under `run_folders("overwrite")` (--overwrite: the old run is
moved aside, and deleted only once the new one has finished; if the new one fails or is
interrupted, the old one comes back) or `run_folders("resume")` (--resume: the command
continues what is there).
"""

from __future__ import annotations

import contextlib
import csv
import errno
import hashlib
import io
import json
import math
import os
import re
import shutil
import time
import tomllib
import zipfile
import zlib
from contextvars import ContextVar
from pathlib import Path
from typing import Any, Literal

import numpy as np
import tomli_w

from motorlab import claims
from motorlab.claims import (  # noqa: F401 - re-exported: run folders are written through runs
    SUMMARY,
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    current_umask,
    is_complete,
)
from motorlab.errors import MotorlabError, StorageError, mask_secrets
from motorlab.provenance import describe
from motorlab.user_modules import imported_names, remember

CONFIG = "config.toml"
ENVIRONMENT = "environment.json"
METRICS = "metrics.csv"
POLICY_JSON = "policy.json"  # a run's policy: its type, spaces and numbers (motorlab.policies reads it)


def default_out(step: str) -> Path:
    """`runs/<step>-<timestamp>` under the current directory."""
    return Path("runs") / f"{step}-{time.strftime('%Y%m%d-%H%M%S')}"


def atomic_write_npz(path: Path, **arrays: Any) -> None:
    """Plain arrays in one .npz (np.savez, no pickle), written atomically."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip's first entry, or an empty zip's end record


class NpzUnreadable(Exception):
    """Why a file is not a plain .npz archive, in words for a one-line message."""


def read_npz(path: Path) -> dict[str, np.ndarray]:
    """Every array of a plain .npz archive at `path`, never unpickling (transitions, activations: the
    files motorlab writes with `atomic_write_npz`).

    Raises:
        NpzUnreadable: not an .npz archive (random bytes, an .npy file, a pickle), a damaged or
            cut-short one, or arrays of Python objects; its text says which, never numpy's
            advice to load the file unsafely. The caller names the file and the fix.
    """
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        raise NpzUnreadable(f"cannot read it: {e.strerror or e}") from None
    if head not in ZIP_MAGIC:
        raise NpzUnreadable("it is not an .npz archive")
    try:
        with np.load(path, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except ValueError as e:
        if "pickle" in str(e):  # numpy's own text suggests unpickling: never shown
            raise NpzUnreadable("it holds arrays of Python objects, which motorlab never unpickles") from None
        raise NpzUnreadable(f"an array in it is damaged: {first_line(e)}") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, KeyError) as e:
        raise NpzUnreadable(f"the archive is damaged or cut short: {first_line(e) or type(e).__name__}") from None


def first_line(e: Exception) -> str:
    return (str(e).strip().splitlines() or [""])[0]


def _plain(value: Any) -> Any:
    """JSON-safe value: numpy scalars to Python, NaN/Inf to null, and every string as motorlab records it,
    credentials masked (`mask_secrets`): whatever a run folder's JSON and TOML hold passes here."""
    if isinstance(value, str):
        return mask_secrets(value)
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {mask_secrets(str(k)): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):
        return _plain(value.tolist())
    return value


def write_json(path: Path, data: dict[str, Any]) -> None:
    atomic_write_text(Path(path), json.dumps(_plain(data), indent=2, sort_keys=False) + "\n")


def read_text_file(path: Path, parse, fmt: str, fix: str) -> dict[str, Any]:
    """Parse a file a step wrote; a missing or corrupt file gives one clear error."""
    path = Path(path)
    if not path.is_file():
        raise MotorlabError(f"{path} is missing; {fix}")
    try:
        return parse(path.read_text())
    except (ValueError, UnicodeDecodeError) as e:  # JSONDecodeError and TOMLDecodeError are ValueErrors
        raise MotorlabError(f"{path} is not valid {fmt} ({e}); re-run the step that wrote it.") from None


def read_json(path: Path) -> dict[str, Any]:
    return read_text_file(path, json.loads, "JSON", "run the step that writes it first.")


def _config_toml(config: dict[str, Any]) -> str:
    """Settings as TOML text (None values dropped: TOML has no null)."""

    def drop_none(d: Any) -> Any:
        if isinstance(d, dict):
            return {k: drop_none(v) for k, v in d.items() if v is not None}
        return d

    return tomli_w.dumps(drop_none(_plain(config)))


def write_config(run_dir: Path, config: dict[str, Any]) -> None:
    """Resolved settings as config.toml, and what they ran on as environment.json (with the
    user's modules that registered its envs: a fresh process reading the folder imports them)."""
    write_toml(Path(run_dir) / CONFIG, config)
    write_json(Path(run_dir) / ENVIRONMENT, {**describe(), "imports": imported_names()})


def recall_imports(run_dir: Path) -> None:
    """Pass on the user modules a run folder's environment.json recorded: the next env built
    (here or in a worker) imports them, as the run did."""
    try:
        recorded = json.loads((Path(run_dir) / ENVIRONMENT).read_text()).get("imports") or []
    except (OSError, ValueError, AttributeError):
        return  # older folders, or none: their envs need no module of the user's
    remember(recorded if isinstance(recorded, list) else [])


def finished_with(run_dir: Path, config: dict[str, Any], filename: str = CONFIG) -> bool:
    """True when run_dir finished (summary.json) with exactly these settings, as written to TOML
    in `filename` (config.toml by default)."""
    return is_complete(run_dir) and toml_holds(Path(run_dir) / filename, config)


def toml_holds(path: Path, config: dict[str, Any]) -> bool:
    """True when the TOML file at `path` holds exactly `config` (False if missing or damaged)."""
    try:
        return tomllib.loads(Path(path).read_text()) == tomllib.loads(_config_toml(config))
    except (OSError, ValueError, UnicodeDecodeError):
        return False  # missing or damaged: run the step again


def write_toml(path: Path, config: dict[str, Any]) -> None:
    """`config` as TOML at `path`, whole; a file that already says exactly this is left as it is (its
    time stays when the run wrote it: a training writes config.toml as it starts, and `finish` again)."""
    text = _config_toml(config)
    with contextlib.suppress(OSError, UnicodeDecodeError):
        if Path(path).is_file() and not Path(path).is_symlink() and Path(path).read_text() == text:
            return
    atomic_write_text(Path(path), text)


def read_config(run_dir: Path) -> dict[str, Any]:
    return read_text_file(Path(run_dir) / CONFIG, tomllib.loads, "TOML",
                           f"{run_dir} is not a motorlab run folder.")


def write_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    """summary.json (the run is finished), then the marker names what the folder holds: what a later
    --overwrite may delete with it (files it writes after, plots, are added when its lock is given back)."""
    write_json(Path(run_dir) / SUMMARY, summary)
    with contextlib.suppress(OSError):  # the run has finished: a full disk here costs the list, not the run
        claims.record_entries(run_dir)


def run_path(out: Path | None, step: str) -> Path:
    """The run folder to use: `out`, or runs/<step>-<timestamp>."""
    run_dir = Path(out) if out is not None else default_out(step)
    if run_dir.exists() and not run_dir.is_dir():
        raise MotorlabError(f"--out {run_dir} is a file; choose a folder path.")
    return run_dir


# ---- what a command may do to a folder: only what its marker allows --------------------------

STUDY = "study"  # the kind a study's folder is marked with (`motorlab run`; a sweep or tune trial of a recipe)
FolderMode = Literal["new", "resume", "overwrite"]
_MODE: ContextVar[FolderMode] = ContextVar("motorlab_run_folder_mode", default="new")
_REPLACED: ContextVar[list[tuple[Path, Path]] | None] = ContextVar("motorlab_replaced_runs", default=None)
ASIDE = ".replaced-"  # a run --overwrite moved aside: <parent>/.<name>.replaced-<time>-<pid>
_ASIDE_TAIL = re.compile(r"\d{8}-\d{6}-(\d+)")  # what follows ASIDE: the time and the process that moved it


@contextlib.contextmanager
def run_folders(mode: FolderMode = "new"):
    """The run folders made inside the block (`prepare_run_dir`) treat a finished run in their way:
    "new" refuses to write there, "resume" continues it (the command knows how), "overwrite"
    replaces it whole. A replaced run is moved aside, not deleted, until the block ends: deleted
    when the new run finished, moved back when it did not (an error, Ctrl-C). Old TensorBoard
    events therefore never mix with new ones, and a failed --overwrite loses nothing. The run
    folders locked inside the block (one writer each) are given back when it ends."""
    replaced: list[tuple[Path, Path]] = []
    tokens = _MODE.set(mode), _REPLACED.set(replaced)
    try:
        with claims.lock_scope():
            try:
                yield
            except BaseException:
                for run_dir, aside in reversed(replaced):
                    _restore(run_dir, aside)
                raise
            else:
                for run_dir, aside in replaced:
                    _settle(run_dir, aside)
    finally:
        _MODE.reset(tokens[0])
        _REPLACED.reset(tokens[1])


def folder_mode() -> FolderMode:
    """The mode of the `run_folders` block this code runs in ("new" outside any)."""
    return _MODE.get()


def replacements() -> list[tuple[Path, Path]] | None:
    """The runs the current `run_folders` block moved aside (None outside any): code that hands work
    to threads (which do not inherit the block) passes it on to `move_aside`."""
    return _REPLACED.get()


def _aside_prefix(name: str) -> str:
    """The start of the name a run called `name` gets when moved aside: `.<name>.replaced-`, or, where
    that would be too long for a file name, a hash of the name in its place (exact all the same)."""
    prefix = f".{name}{ASIDE}"
    if len(os.fsencode(prefix)) + 40 > 255:  # the time, the pid and room to spare
        prefix = f".{hashlib.sha256(os.fsencode(name)).hexdigest()[:24]}{ASIDE}"
    return prefix


def move_aside(run_dir: Path, replaced: list[tuple[Path, Path]]) -> Path:
    """Move a run out of the way of the run that replaces it, recorded in `replaced` (a
    `run_folders` block's list: deleted when the block ends well, put back otherwise)."""
    aside = run_dir.parent / f"{_aside_prefix(run_dir.name)}{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    os.replace(run_dir, aside)  # one rename: the old run is whole, either here or there
    replaced.append((run_dir, aside))
    return aside


def _restore(run_dir: Path, aside: Path) -> None:
    """Put a replaced run back where it was (the run that was to replace it did not finish). What
    stands in its place is removed only when it is motorlab's unfinished run that no other process
    is writing; otherwise the replaced run stays aside, whole, for the next `recover`."""
    if not aside.is_dir():
        return
    if run_dir.exists() or run_dir.is_symlink():
        if not _disposable(run_dir):
            return
        shutil.rmtree(run_dir, ignore_errors=True)
    os.replace(aside, run_dir)


def _disposable(run_dir: Path) -> bool:
    """True when `run_dir` may be deleted to put a replaced run back: an unfinished motorlab run (or
    an empty folder) that no other process holds."""
    if run_dir.is_symlink() or not run_dir.is_dir() or is_complete(run_dir) or not claims.free(run_dir):
        return False
    try:
        return claims.read_claim(run_dir) is not None or not claims.entries(run_dir)
    except (MotorlabError, OSError):
        return False


def _asides(run_dir: Path) -> list[Path]:
    """Runs an --overwrite of `run_dir` moved aside and left there: its process was killed (one
    still running owns its aside, named with its process id). Found by their exact names: `run_dir`'s
    own prefix followed by a time and a pid, matched whole (never a pattern: a name with `[`, `*` or
    `?` matches only itself)."""
    parent = run_dir.parent
    if not parent.is_dir():
        return []
    prefix = _aside_prefix(run_dir.name)
    found = []
    with os.scandir(parent) as listing:
        for entry in listing:
            if not entry.name.startswith(prefix):
                continue
            tail = _ASIDE_TAIL.fullmatch(entry.name[len(prefix):])
            if tail is not None and entry.is_dir(follow_symlinks=False) and not _alive(tail.group(1)):
                found.append(parent / entry.name)
    return sorted(found)


def _alive(pid: str) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ValueError, ProcessLookupError):
        return False
    except PermissionError:
        pass  # another user's process
    return True


def recover(run_dir: Path) -> None:
    """Settle an --overwrite of `run_dir` that was killed: the old run comes back where the new one
    did not finish; where it did, the old one is deleted."""
    for aside in _asides(Path(run_dir)):
        _settle(Path(run_dir), aside)


def _settle(run_dir: Path, aside: Path) -> None:
    """The replaced run `aside` goes for good where its replacement finished, else back in place."""
    if is_complete(run_dir):
        shutil.rmtree(aside, ignore_errors=True)
    else:
        _restore(run_dir, aside)


def finished_run_message(run_dir: Path, resumable: bool = False) -> str:
    """The one line refusing to write into a finished run."""
    resume = "--resume to continue it, " if resumable else ""
    return (f"{run_dir} holds a finished run (its summary.json); give another --out, or {resume}--overwrite "
            "to replace it.")


def refuse_finished(run_dir: Path, resumable: bool = False, kind: str | None = None,
                    inputs: frozenset[str] = frozenset()) -> None:
    """Raise unless `run_dir` may be written by a run of `kind` (None: any kind's run folder) in the
    current folder mode (see `run_folders`). Call it before any work, so a refusal costs nothing.

    A folder is motorlab's to write when it is new or empty, or when its marker (motorlab.claims)
    says it holds a run of this kind: then a finished run is refused unless the command resumes or
    overwrites it, and --overwrite refuses a folder that has gained entries its run did not leave
    there. Any other folder is refused, whatever the mode: motorlab never writes into, replaces or
    resumes what it did not make. `inputs`: names the command itself reads there, which a folder not
    yet marked may hold (a search's study database the user made for it).

    Raises:
        MotorlabError: one line naming the folder, why, and the fix.
    """
    run_dir = Path(run_dir)
    recover(run_dir)
    if not run_dir.is_dir():
        if run_dir.exists():
            raise MotorlabError(f"--out {run_dir} is a file; choose a folder path.")
        return
    claim = claims.read_claim(run_dir)
    held = claims.entries(run_dir)
    if claim is None:
        if held - inputs:
            older = " (a run folder an older motorlab wrote has none either: move it away first)" \
                if {SUMMARY, ENVIRONMENT} <= held else ""
            raise MotorlabError(
                f"{run_dir} is not empty and is not a motorlab run folder (it has no {claims.MARKER}){older}; motorlab "
                "writes only into new or empty folders and its own runs, and replaces nothing else: choose another --out.")
        return
    if kind is not None and claim.kind != kind:
        raise MotorlabError(f"{run_dir} holds a motorlab {claim.kind} run, not a {kind} run; a {kind} command neither "
                            "replaces nor continues it: choose another --out.")
    mode = folder_mode()
    if mode == "new" and is_complete(run_dir):
        raise MotorlabError(finished_run_message(run_dir, resumable))
    foreign = sorted(claims.contents(run_dir) - set(claim.files)) if mode == "overwrite" and claim.files is not None \
        else []
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise MotorlabError(f"{run_dir} holds {shown}, which its run did not write; --overwrite would delete "
                            "them: move them out first, or choose another --out.")


def prepare_run_dir(out: Path | None, step: str, resumable: bool = False, kind: str | None = None) -> Path:
    """Create the run folder of a run of `kind` (default: `step`; `step` names the default folder,
    runs/<step>-<time>), marked as motorlab's, locked for this process (until the innermost
    `run_folders` block or `claims.lock_scope` ends), with a stale summary.json removed so the folder
    does not look complete until this run finishes. Call it only once the settings are known to be
    valid, so a mistake never spoils a finished run.

    Raises:
        MotorlabError: the folder may not be written (see `refuse_finished`), another process is
            writing it, it holds a symbolic link, or it cannot be made.
    """
    kind = kind or step
    run_dir = run_path(out, step)
    refuse_finished(run_dir, resumable, kind)
    if run_dir.is_dir():
        claims.lock(run_dir)  # before anything is written; then the checks again, as the holder
        refuse_finished(run_dir, resumable, kind)
        replaced = _REPLACED.get()
        if folder_mode() == "overwrite" and claims.entries(run_dir) and replaced is not None:
            move_aside(run_dir, replaced)
    make_folder(run_dir)
    claims.lock(run_dir)  # a new folder (or the same one: this process holds it already)
    claims.refuse_links(run_dir)
    claims.mark(run_dir, kind)
    (run_dir / SUMMARY).unlink(missing_ok=True)
    return run_dir


def wrote_into(path: Path) -> None:
    """motorlab wrote `path` into a finished run's folder after the run (`motorlab plot`'s figures, `motorlab
    report`'s page, a study's figures of its steps, a sweep's record of a trial): the run folder it lies in
    lists it in its marker, so a later --overwrite does not take it for a file of the user's."""
    for folder in (Path(path), *Path(path).parents):
        if os.path.lexists(folder / claims.MARKER):
            with contextlib.suppress(OSError, MotorlabError):  # the list is best effort: the files are written
                claims.record_entries(folder)
            return


def claim_folder(run_dir: Path, kind: str, inputs: frozenset[str] = frozenset()) -> Path:
    """Make `run_dir` a marked run folder of `kind` without locking it, for a run another process
    will write (a study's training step): the same refusals as `prepare_run_dir`, which that
    process then calls (`inputs`: see `refuse_finished`).

    Raises:
        MotorlabError: as `refuse_finished`, or another process is writing it.
    """
    refuse_finished(run_dir, True, kind, inputs)
    make_folder(run_dir)
    if not claims.free(run_dir):
        raise MotorlabError(claims.busy_message(run_dir))
    claims.refuse_links(run_dir)
    claims.mark(run_dir, kind)
    return run_dir


def make_folder(path: Path) -> Path:
    """mkdir -p, with one line for a folder that cannot be made (permissions, a read-only disk)."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        if not os.access(path, os.W_OK | os.X_OK):
            raise PermissionError(errno.EACCES, "permission denied", str(path))
    except OSError as e:  # the one table of what the system refused (errors.StorageError), else in words here
        raise StorageError.of(e) or MotorlabError(
            f"cannot write {e.filename or path}: {os.strerror(e.errno).lower() if e.errno else type(e).__name__}; "
            "choose an --out folder you can write to.") from None
    return path


def inside(root: Path, path: Path, what: str) -> Path:
    """`path`, checked to resolve inside `root` (a study writes nowhere else, whatever a recipe says).

    Raises:
        MotorlabError: naming `what` wrote outside.
    """
    resolved, top = Path(path).resolve(), Path(root).resolve()
    if resolved != top and top not in resolved.parents:
        raise MotorlabError(f"{what} would write to {path}, outside {root}; name it with letters, digits, '-', "
                            "'_' and '.' only.")
    return Path(path)


def require_run_dir(path: Path) -> Path:
    """Check that `path` is a finished run folder."""
    path = Path(path)
    if not path.exists():
        raise MotorlabError(f"run folder {path} does not exist; check the path or run `motorlab train` first.")
    if not path.is_dir():
        raise MotorlabError(f"{path} is not a folder; pass a run folder written by `motorlab train`.")
    if not os.access(path, os.R_OK | os.X_OK):
        raise MotorlabError(f"run folder {path} is not readable; check its permissions.")
    recover(path)
    if not is_complete(path):
        damaged = (path / SUMMARY).is_file()
        raise MotorlabError(
            f"{path} has {'a damaged' if damaged else 'no'} {SUMMARY}: the run did not finish (or this is not a run "
            "folder); re-run it."
        )
    recall_imports(path)
    return path


class MetricsWriter:
    """Append rows to metrics.csv, one whole line per write, flushed at once.

    `keep_until` (resuming from a checkpoint at that step): keep the rows written up to it
    and append after them; rows past it (redone after the resume) and a line torn by a kill
    are dropped first, so the file never holds a duplicated or torn row."""

    def __init__(self, path: Path, fields: list[str], keep_until: int | None = None):
        self.path = Path(path)
        self.fields = fields
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if keep_until is not None and self.path.is_file():
            atomic_write_text(self.path, _rows_until(self.path, fields, keep_until))
            self._f = _open_no_follow(self.path, os.O_APPEND)
            self._writer = csv.DictWriter(self._f, fieldnames=fields, extrasaction="ignore")
            return
        self._f = _open_no_follow(self.path, os.O_TRUNC)
        self._writer = csv.DictWriter(self._f, fieldnames=fields, extrasaction="ignore")
        self._writer.writeheader()
        self._f.flush()

    def write(self, row: dict[str, Any]) -> None:
        self._writer.writerow({k: _plain(row.get(k)) for k in self.fields})
        self._f.flush()

    def close(self) -> None:
        self._f.close()


def _open_no_follow(path: Path, how: int):
    """A text file opened for writing that is never a link's target (ELOOP where `path` is a link: a
    write through it would land outside the run folder)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | how, 0o666)
    return os.fdopen(fd, "a" if how == os.O_APPEND else "w", newline="")


def _rows_until(path: Path, fields: list[str], steps: int) -> str:
    """metrics.csv's header and its whole rows with timesteps <= steps, in `fields`' columns: a file
    written by an older motorlab (other columns) keeps every row, its cells moved under their names
    (a column it lacks stays empty; one `fields` lacks is dropped)."""
    text = path.read_text(errors="replace")
    lines = text.split("\n")
    if not text.endswith("\n"):
        lines = lines[:-1]  # the last line was cut short
    old = next(csv.reader([lines[0].rstrip("\r")]), []) if lines else []
    if "timesteps" not in old:
        old = fields  # no header to read: the rows are taken as the current columns
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=fields, extrasaction="ignore")
    writer.writeheader()
    for line in lines[1:]:
        cells = next(csv.reader([line.rstrip("\r")]), [])
        if len(cells) != len(old):
            continue  # torn by a kill
        row = dict(zip(old, cells))
        try:
            if float(row["timesteps"]) <= steps:
                writer.writerow(row)
        except ValueError:
            continue
    return out.getvalue()


def last_timesteps(run_dir: Path) -> int:
    """Env steps of the last whole row of a run's metrics.csv so far (0 when there is none):
    how far a training running in another process has got. Reads only the file's tail."""
    path = Path(run_dir) / METRICS
    try:
        with open(path, "rb") as f:
            f.seek(max(0, path.stat().st_size - 4096))
            lines = f.read().decode(errors="replace").split("\n")[:-1]  # the part after the last newline may be torn
    except OSError:
        return 0
    for line in reversed(lines):
        try:
            return int(float(line.split(",", 1)[0]))
        except ValueError:
            continue  # the header, or a line cut by the 4 KB window
    return 0


def read_metrics(run_dir: Path) -> list[dict[str, float]]:
    """metrics.csv as a list of rows with float values (missing values as NaN)."""
    path = Path(run_dir) / METRICS
    if not path.is_file():
        raise MotorlabError(f"{path} is missing; this run wrote no training metrics.")
    return read_number_rows(path)


def read_number_rows(path: Path) -> list[dict[str, float]]:
    """A CSV of numbers a run wrote (metrics.csv, an mbrl loop's curve.csv) as rows of floats, empty
    values as NaN; a value that is not a number is one line saying the file is damaged."""
    rows = []
    with open(path, newline="") as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                rows.append({k: (float(v) if v not in ("", None) else float("nan")) for k, v in row.items()})
            except (TypeError, ValueError):
                raise MotorlabError(f"{path} line {line} holds a value that is not a number; "
                                    "the file is damaged: re-run the step.") from None
    return rows
