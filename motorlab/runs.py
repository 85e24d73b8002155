"""Run folders: one per step, written so that nothing is ever half-written.

A run folder holds `config.toml` (resolved settings), `summary.json` (headline
numbers, flat keys), `metrics.csv`, `tensorboard/`, artifacts, `plots/`.
`summary.json` is written last: a folder without it is an unfinished run.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from motorlab.environment import describe
from motorlab.errors import MotorlabError
from motorlab.user_modules import imported_names, remember

SUMMARY = "summary.json"
CONFIG = "config.toml"
ENVIRONMENT = "environment.json"
METRICS = "metrics.csv"


def default_out(step: str) -> Path:
    """`runs/<step>-<timestamp>` under the current directory."""
    return Path("runs") / f"{step}-{time.strftime('%Y%m%d-%H%M%S')}"


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~current_umask()  # what open() gives; mkstemp's 0600 would hide plots and videos from others


@contextlib.contextmanager
def atomic_path(path: Path, suffix: str = ".tmp"):
    """A temp file beside `path` to write to (by name, e.g. for ffmpeg); renamed over `path` when
    the block ends, removed if it fails. It gets the permissions open() would give, not mkstemp's 0600."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
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


def atomic_write_npz(path: Path, **arrays: Any) -> None:
    """Plain arrays in one .npz (np.savez, no pickle), written atomically."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def _plain(value: Any) -> Any:
    """JSON-safe value: numpy scalars to Python, NaN/Inf to null."""
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
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
    atomic_write_text(Path(path), _config_toml(config))


def read_config(run_dir: Path) -> dict[str, Any]:
    return read_text_file(Path(run_dir) / CONFIG, tomllib.loads, "TOML",
                           f"{run_dir} is not a motorlab run folder.")


def write_summary(run_dir: Path, summary: dict[str, Any]) -> None:
    write_json(Path(run_dir) / SUMMARY, summary)


def is_complete(run_dir: Path) -> bool:
    return (Path(run_dir) / SUMMARY).is_file()


def run_path(out: Path | None, step: str) -> Path:
    """The run folder to use: `out`, or runs/<step>-<timestamp>."""
    run_dir = Path(out) if out is not None else default_out(step)
    if run_dir.exists() and not run_dir.is_dir():
        raise MotorlabError(f"--out {run_dir} is a file; choose a folder path.")
    return run_dir


def prepare_run_dir(out: Path | None, step: str) -> Path:
    """Create the run folder; a stale summary.json is removed so the folder
    does not look complete until this run finishes. Call it only once the
    settings are known to be valid, so a mistake never spoils a finished run."""
    run_dir = run_path(out, step)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / SUMMARY).unlink(missing_ok=True)
    return run_dir


def require_run_dir(path: Path) -> Path:
    """Check that `path` is a finished run folder."""
    path = Path(path)
    if not path.exists():
        raise MotorlabError(f"run folder {path} does not exist; check the path or run `motorlab train` first.")
    if not path.is_dir():
        raise MotorlabError(f"{path} is not a folder; pass a run folder written by `motorlab train`.")
    if not os.access(path, os.R_OK | os.X_OK):
        raise MotorlabError(f"run folder {path} is not readable; check its permissions.")
    if not is_complete(path):
        raise MotorlabError(
            f"{path} has no {SUMMARY}: the run did not finish (or this is not a run folder); re-run it."
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
            self._f = open(self.path, "a", newline="")
            self._writer = csv.DictWriter(self._f, fieldnames=fields, extrasaction="ignore")
            return
        self._f = open(self.path, "w", newline="")
        self._writer = csv.DictWriter(self._f, fieldnames=fields, extrasaction="ignore")
        self._writer.writeheader()
        self._f.flush()

    def write(self, row: dict[str, Any]) -> None:
        self._writer.writerow({k: _plain(row.get(k)) for k in self.fields})
        self._f.flush()

    def close(self) -> None:
        self._f.close()


def _rows_until(path: Path, fields: list[str], steps: int) -> str:
    """metrics.csv's header and its whole rows with timesteps <= steps."""
    text = path.read_text(errors="replace")
    lines = text.split("\n")
    if not text.endswith("\n"):
        lines = lines[:-1]  # the last line was cut short
    header = ",".join(fields)
    kept = [header]
    for line in lines[1:]:
        cells = next(csv.reader([line]), [])
        if len(cells) != len(fields):
            continue
        try:
            if float(cells[0]) <= steps:
                kept.append(line.rstrip("\r"))
        except ValueError:
            continue
    return "\r\n".join(kept) + "\r\n"  # csv's own line ending


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
    rows = []
    with open(path, newline="") as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                rows.append({k: (float(v) if v not in ("", None) else float("nan")) for k, v in row.items()})
            except (TypeError, ValueError):
                raise MotorlabError(f"{path} line {line} holds a value that is not a number; "
                                    "the file is damaged: re-run the step.") from None
    return rows
