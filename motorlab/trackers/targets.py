"""What the trackers are told: where to track (Target, from --track), a tracked run as the backends see it
(RunInfo), its settings and numbers flattened, and the files of a run folder a tracked run gets."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from motorlab.errors import MotorlabError, mask_url

BACKENDS = ("mlflow", "wandb")
FLUSH_SECONDS = 2.0  # buffered scalars go to the trackers this often
CLOSE_SECONDS = 60.0  # the longest the end of a run (or a parent's start) waits for its trackers

# The files of a run folder a tracked run gets: at the top, by suffix; under these folders, all of them
FILE_SUFFIXES = (".json", ".toml", ".csv", ".txt", ".html", ".log", ".png", ".mp4")
FILE_FOLDERS = ("plots", "videos")
MODEL_PREFIXES = ("policy.", "model.")  # weights and their descriptions are the run folder's, not the tracker's


@dataclass(frozen=True)
class Target:
    """One tracker: `backend` (mlflow or wandb) and `where` (MLflow's tracking URI, W&B's project)."""

    backend: str
    where: str | None = None

    def text(self) -> str:
        return self.backend + (f"={self.where}" if self.where else "")


def parse(values: list[str] | tuple[str, ...] | str | None) -> list[Target]:
    """`--track` values (a list, or one text separated by spaces) as targets.

    Raises:
        MotorlabError: an unknown tracker, or one named twice.
    """
    if isinstance(values, str):
        values = values.split()
    targets: dict[str, Target] = {}
    for value in values or ():
        backend, sep, where = value.strip().partition("=")
        backend = backend.lower()
        if backend not in BACKENDS or (sep and not where):
            shown = value.strip().partition("=")[0] + sep + mask_url(where)
            raise MotorlabError(f"--track {shown!r}: choose mlflow, mlflow=URI (sqlite:///PATH, file:///PATH, "
                                "http://HOST:PORT), wandb or wandb=PROJECT.")
        if backend in targets:
            raise MotorlabError(f"--track {backend} is given twice; give each tracker once.")
        targets[backend] = Target(backend, where or None)
    return list(targets.values())


# ---- what the trackers are told ----------------------------------------------------------------


@dataclass
class RunInfo:
    """A tracked run as the backends see it."""

    name: str
    kind: str
    run_dir: Path | None
    config: dict[str, Any]
    tags: dict[str, str]
    parent: dict[str, Any] = field(default_factory=dict)  # the parent's handoff, per backend
    group: str | None = None  # W&B's group: the parent's, or this run's own when it is a parent
    nested: bool = False  # started under a parent (which says where the runs are)


def flat(config: dict[str, Any], prefix: str = "") -> dict[str, str]:
    """Nested settings as one level ("env.id": "InvertedPendulum-v5"), values as text (JSON for numbers and lists)."""
    out: dict[str, str] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            out.update(flat(value, name + "."))
        else:
            out[name] = value if isinstance(value, str) else json.dumps(value, default=str)
    return out


def numbers(summary: dict[str, Any]) -> dict[str, float]:
    """The numbers of a summary (booleans as 0 and 1), for the tracker's final metrics."""
    return {k: float(v) for k, v in summary.items()
            if isinstance(v, (int, float)) and (isinstance(v, bool) or math.isfinite(v))}


def run_files(folder: Path) -> list[tuple[Path, str]]:
    """The files of a run folder a tracked run gets, each with the folder it goes to inside the run ("" at the top)."""
    folder = Path(folder)
    files = [(p, "") for p in sorted(folder.iterdir()) if p.is_file() and p.suffix in FILE_SUFFIXES
             and not p.name.startswith((".", *MODEL_PREFIXES))] if folder.is_dir() else []
    for sub in FILE_FOLDERS:
        for p in sorted((folder / sub).rglob("*")) if (folder / sub).is_dir() else ():
            if p.is_file() and not p.name.startswith("."):
                files.append((p, p.parent.relative_to(folder).as_posix()))
    return files
