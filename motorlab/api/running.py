"""Running one step kind from Python: settings from keyword arguments, the door (`StepKind.perform`), a `Result`.

Every function of the API ends here, so that a script runs exactly what the CLI runs: the kind's
settings model checks the arguments (a `MotorlabError` with the CLI's message), its `run` writes
the folder, and `load` opens it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.console import Console

from motorlab.api.views import Result, as_path, load
from motorlab.errors import MotorlabError
from motorlab.kinds import KINDS
from motorlab.runs import run_folders
from motorlab.settings import Settings
from motorlab.stepkind import StepKind

Track = str | list[str] | None


def provided_file(kind: str) -> str | None:
    """The file inside a `kind` run folder that later steps read (a fit's sar.npz), if any."""
    provides = KINDS[kind].provides if kind in KINDS else None
    return provides.file if provides else None


def path_of(value: Any) -> Any:
    """A step's input as its settings take it: `Result`s become their folder or file, lists elementwise."""
    if isinstance(value, Result):
        return as_path(value, provided_file)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (list, tuple)):
        return [path_of(v) for v in value]
    if isinstance(value, dict):
        return {k: path_of(v) for k, v in value.items()}
    return value


def settings(kind: StepKind, **fields: Any) -> Settings:
    """The settings of a `kind` step from keyword arguments (None: the default).

    Raises:
        MotorlabError: a wrong or unknown setting, named as the CLI names it.
    """
    return kind.make(**{k: path_of(v) for k, v in fields.items()})


def run(kind: StepKind, checked: Settings, out: str | Path | None, progress: bool, track: Track = None,
        overwrite: bool = False) -> Result:
    """Run a `kind` step with `checked` settings into `out` through its door (`StepKind.perform`) and open
    its folder (`overwrite`: replace a finished run there, as --overwrite does; without it, a finished run
    in `out` is refused). `track`: this run only (None: as the enclosing `motorlab.tracking` block says)."""
    summary = kind.perform(checked, Path(out) if out is not None else None, folders="overwrite" if overwrite else "new",
                           track=track, console=console(), progress=progress)
    return load(summary.run_dir)


def run_kind(kind: StepKind, out: str | Path | None = None, progress: bool = True, track: Track = None,
             **fields: Any) -> Result:
    """`settings` then `run`: one step from keyword arguments (`overwrite=True`: see `run`)."""
    overwrite = bool(fields.pop("overwrite", False))
    return run(kind, settings(kind, **fields), out, progress, track, overwrite)


def folders(resume: bool = False, overwrite: bool = False):
    """The `run_folders` block of a study, sweep or search: `resume` keeps what finished in its
    folder, `overwrite` replaces it; neither refuses a folder that holds a finished one."""
    if resume and overwrite:
        raise MotorlabError("resume keeps what finished in out and overwrite replaces it; give one of them.")
    return run_folders("resume" if resume else "overwrite" if overwrite else "new")


def console() -> Console:
    """Where steps print their tables: the notebook's output in Jupyter (Rich renders HTML there),
    else stderr as the CLI does, so that a script's stdout stays its own."""
    return Console() if _in_notebook() else Console(stderr=True)


def _in_notebook() -> bool:
    return Console().is_jupyter
