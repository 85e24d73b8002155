"""What a command is made of: a settings model, a run, and what it prints.

Every `motorlab` command is one `Command` object beside its domain code. The step kinds
(motorlab.stepkind: train, evaluate, dynamics fit, ...) are commands that write one run folder;
the others (export, report, run, sweep, tune, ...) are commands too, each beside what it runs.
The CLI (motorlab.cli), the child processes (motorlab.worker) and the Python API all build a
command's settings from its model and call `invoke`, so an option's type, default, check and
help are written once, in the model.

How a command is run, as opposed to what it does, is its `Invocation`: the folder it writes,
whether a finished one may be replaced or resumed, and where it is tracked. Those are not
settings (config.toml does not record them) but they are a model too, so the CLI's options for
them come from one place and a child process gets them in its job file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar, get_args, get_origin

from pydantic import BaseModel, Field, ValidationError, field_validator
from rich.console import Console

from motorlab import trackers
from motorlab.errors import MotorlabError
from motorlab.runs import FolderMode, run_folders
from motorlab.settings import Settings, StrictModel


class Invocation(StrictModel):
    """How a command writes its folder: `--out` and `--overwrite`."""

    out: Path | None = Field(None, description="Run folder to write (default: runs/<step>-<timestamp>)")
    overwrite: bool = Field(False, description=(
        "Replace the finished run in --out, whole (TensorBoard events too). Without it, a folder holding a finished "
        "run is refused. The old run is deleted only once the new one finishes; if the new one fails or is "
        "interrupted, the old one is put back"))

    def mode(self) -> FolderMode:
        """The run-folder mode (motorlab.runs.run_folders) these options ask for."""
        return "overwrite" if self.overwrite else "new"


class Tracked(Invocation):
    """A command whose runs an experiment tracker may mirror: `--track`."""

    track: list[str] | None = Field(None, description=(
        "Also log the run, live, to an experiment tracker (repeatable): mlflow (a SQLite store: $MLFLOW_TRACKING_URI, "
        "else ./mlflow.db), mlflow=URI (sqlite:///PATH, file:///PATH, http://HOST:PORT), wandb (Weights & Biases, "
        "offline without an API key: `wandb sync` uploads it later) or wandb=PROJECT. Settings, TensorBoard's "
        "scalars, summary and plots; a sweep's, study's or tune's runs nest under theirs. Needs pip install "
        "'motorlab[mlflow]' or 'motorlab[wandb]'"))

    @field_validator("track", mode="before")
    @classmethod
    def _one_or_many(cls, v: Any) -> Any:
        return v.split() if isinstance(v, str) else v


class Resumable(Tracked):
    """A study, sweep or search, which can go on with what finished in its folder: `--resume`."""

    resume: bool = Field(False, description=(
        "Run again into a finished --out, keeping what finished there with the same settings (a study's steps, a "
        "sweep's trials, a search's trials)"))

    def mode(self) -> FolderMode:
        if self.resume and self.overwrite:
            raise MotorlabError("--resume keeps what finished in --out and --overwrite replaces it; give one of them.")
        return "resume" if self.resume else super().mode()


class NoFolder(StrictModel):
    """A command that writes no run folder (or only a file it is given)."""

    def mode(self) -> FolderMode:
        return "new"


S = TypeVar("S", bound=Settings)


class Command(Generic[S]):
    """One command. Subclasses set `settings` (the model), `command` (the words that run it on the
    command line, None: no CLI command), and implement `execute` (or, for step kinds, `run`) and
    `report` (what the command line prints of the result)."""

    name: ClassVar[str]
    command: ClassVar[str | None]
    settings: ClassVar[type[Settings]]
    invocation: ClassVar[type[StrictModel]] = Invocation
    # the fields the command line gives as positional arguments, in order (the rest are options)
    arguments: ClassVar[tuple[str, ...]] = ()
    # other spellings of an option: {"n_synergies": ("--n-synergies", "--n")}
    flags: ClassVar[dict[str, tuple[str, ...]]] = {}
    # the help of --out where it is not a run folder's, and whether it must be given
    out_help: ClassVar[str | None] = None
    out_required: ClassVar[bool] = False
    examples: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for base in getattr(cls, "__orig_bases__", ()):  # class RunCommand(Command[RunSettings]): its model
            if get_origin(base) is Command:
                cls.settings = get_args(base)[0]
        if "command" not in cls.__dict__ and "name" in cls.__dict__:
            cls.command = cls.name.replace("-", " ")

    def help(self) -> str:
        """The command's help: its class docstring."""
        return (type(self).__doc__ or "").strip()

    def validate(self, fields: dict[str, Any]) -> S:
        """Settings from recipe fields, flags or keyword arguments (pydantic.ValidationError when wrong)."""
        return self.settings.model_validate(fields)

    def make(self, how: Any = None, /, **fields: Any) -> S:
        """Settings from keyword arguments (None: the default), as the CLI and the Python API give them.

        `how`, the invocation they run under (`how(...)`), where there is one: what it brings
        (train's --config, --resume) is laid under the given fields before the model judges them
        (`fields_for`), so a flag is judged with the settings it joins, once.

        Raises:
            MotorlabError: one line naming the option and what is wrong with it.
        """
        given = {k: v for k, v in fields.items() if v is not None}
        try:
            return self.validate(given if how is None else self.fields_for(how, given))
        except ValidationError as e:
            raise MotorlabError(option_error(e, self.settings)) from None

    def fields_for(self, how: Any, given: dict[str, Any]) -> dict[str, Any]:
        """The fields `make` validates: `given` (flat, as given), over what the invocation `how`
        brings (a step kind's --config: a run's config.toml). Nothing is validated yet.

        Raises:
            MotorlabError: what the invocation names cannot be read, or does not go with `given`.
        """
        return given

    def how(self, **options: Any) -> Any:
        """The invocation options from keyword arguments (None: the default)."""
        try:
            return self.invocation.model_validate({k: v for k, v in options.items() if v is not None})
        except ValidationError as e:
            raise MotorlabError(option_error(e)) from None

    def invoke(self, settings: S, how: Any, console: Console | None = None, progress: bool = True) -> Any:
        """Run with the run-folder mode and the tracking `how` asks for; returns the result `report` shows."""
        with trackers.tracking(getattr(how, "track", None)), run_folders(how.mode()):
            return self.execute(settings, how, console, progress)

    def execute(self, settings: S, how: Any, console: Console | None, progress: bool) -> Any:
        """The work (inside `invoke`'s run-folder mode and tracking)."""
        raise NotImplementedError

    def report(self, result: Any, settings: S, console: Console) -> None:
        """What the command line prints when the command has run."""


def option_error(e: ValidationError, model: type[BaseModel] | None = None) -> str:
    """One line from a pydantic ValidationError, naming the option as the CLI spells it: with the settings
    `model`, the deepest field of a model along the error's path (a list's position or a table's key names
    no option: `--hidden`, not `--0`)."""
    first = e.errors()[0]
    loc = list(first["loc"])
    name = _option(loc, model) if model is not None else (str(loc[-1]) if loc else "?")
    if name == "id":
        name = "env"
    label = f"--{name.replace('_', '-')}"
    if first["type"] == "extra_forbidden":
        return f"unknown setting {label}"
    if first["type"] == "missing":
        return f"{label} is required; give it (--help says what it takes)"
    given = first.get("input")
    shown = f" {given!r}" if isinstance(given, (int, float, str)) else ""
    return f"{label}{shown}: {first['msg']}"


def _option(loc: list[Any], model: type[BaseModel] | None) -> str:
    """The option an error's path `loc` falls under: its last step that is a field of a settings model."""
    name = str(loc[0]) if loc else "?"
    for key in loc:
        info = model.model_fields.get(key) if isinstance(key, str) and model is not None else None
        if info is None:
            break
        name = key
        model = next((m for m in (*get_args(info.annotation), info.annotation)
                      if isinstance(m, type) and issubclass(m, BaseModel)), None)
    return name
