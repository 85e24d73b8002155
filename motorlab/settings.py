"""The bases of every step's settings and summary. One pydantic model per step kind holds its
defaults, validation and help text, so the CLI, recipes, sweeps and the Python API agree on
them; another types the summary.json its run writes."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field
from pydantic_core import PydanticUndefined


class Settings(BaseModel):
    """A step's settings. Field defaults and descriptions are the defaults and help of the CLI
    options and recipe fields that set them."""

    model_config = ConfigDict(extra="forbid")

    # recipe field names this model takes besides its own fields (e.g. the flat env settings)
    aliases: ClassVar[frozenset[str]] = frozenset()

    @classmethod
    def fields(cls) -> set[str]:
        """The names a recipe step of this kind may set."""
        return set(cls.model_fields) | set(cls.aliases)

    def config(self) -> dict[str, Any]:
        """What config.toml records of these settings."""
        return self.model_dump()


class Summary(BaseModel):
    """summary.json of a run folder: the step's headline numbers under flat, documented keys.
    Kinds whose keys name runs or envs ("<run>.<env>.success_rate") keep those as extra keys."""

    model_config = ConfigDict(extra="allow")

    run_dir: Path | None = Field(None, exclude=True)

    def keys(self) -> dict[str, Any]:
        """What summary.json holds."""
        return self.model_dump()


def help_text(model: type[BaseModel], name: str) -> str:
    """A field's description and, where it has one worth saying, its default: the help of the CLI
    option that sets it."""
    info = model.model_fields[name]
    text = (info.description or "").rstrip(".")
    default = info.get_default(call_default_factory=True)
    if default is PydanticUndefined or default is None or isinstance(default, (bool, dict)):
        return f"{text}."
    shown = ",".join(map(str, default)) if isinstance(default, (list, tuple)) else default
    return f"{text} (default {shown})."
