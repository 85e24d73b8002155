"""The `recipes` command: the bundled recipes, the step kinds a recipe can use (--kinds), or the
JSON Schema of a recipe's steps (--schema).

Listing reads each recipe's name, description and steps as written: it neither validates the
steps (which imports env modules and checks envs) nor needs the values a recipe takes from the
command line (its [inputs], `--set NAME=VALUE`), which `motorlab run` asks for."""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import Field
from rich.console import Console
from rich.markup import escape

from motorlab.command import Command, NoFolder
from motorlab.runs import read_text_file
from motorlab.settings import Settings


class RecipesSettings(Settings):
    """What `motorlab recipes` lists."""

    kinds: bool = Field(False, description="List the step kinds a recipe can use, with their fields and defaults")
    # not `schema`, which would shadow pydantic's BaseModel.schema
    json_schema: bool = Field(False, description="Print the JSON Schema of a recipe's [[steps]] (for editors that "
                              "check TOML against a schema)")


@dataclass(frozen=True)
class RecipeEntry:
    """One bundled recipe as the list shows it."""

    name: str
    description: str
    steps: int


@dataclass(frozen=True)
class KindEntry:
    """One step kind as `--kinds` shows it: its help's first line and its fields (with defaults)."""

    name: str
    about: str
    fields: list[str]


@dataclass
class Listing:
    """What `motorlab recipes` found: the recipes, the kinds (--kinds) or the schema (--schema)."""

    recipes: list[RecipeEntry] = field(default_factory=list)
    kinds: list[KindEntry] = field(default_factory=list)
    schema: dict[str, Any] | None = None


class RecipesCommand(Command[RecipesSettings]):
    """List the bundled recipes (or, with --kinds, the step kinds and their fields)."""

    name = "recipes"
    settings = RecipesSettings
    invocation = NoFolder
    flags = {"json_schema": ("--schema",)}
    examples = (
        "motorlab recipes",
        "motorlab recipes --kinds   # the fields a recipe's steps may set, with their defaults",
        "motorlab recipes --schema > recipe.schema.json   # for an editor",
    )

    def execute(self, settings: RecipesSettings, how: NoFolder, console: Console | None, progress: bool) -> Listing:
        from motorlab.kinds import KINDS
        from motorlab.recipes import bundled, fields_of, step_union

        if settings.json_schema:
            return Listing(schema=step_union().json_schema())
        if settings.kinds:
            return Listing(kinds=[KindEntry(k.name, (k.help().splitlines() or [""])[0],
                                            [field_line(k.settings, f) for f in sorted(fields_of(k))])
                                  for k in KINDS.values()])
        return Listing(recipes=[recipe_entry(name, path) for name, path in sorted(bundled().items())])

    def report(self, result: Listing, settings: RecipesSettings, console: Console) -> None:
        if result.schema is not None:
            console.out(json.dumps(result.schema, indent=2), highlight=False)
            return
        for k in result.kinds:
            console.print(f"[bold]{k.name}[/bold]: {escape(k.about)}")
            console.print("    " + ", ".join(k.fields), highlight=False, markup=False)
        for r in result.recipes:
            console.print(f"[bold]{escape(r.name)}[/bold]: {escape(r.description)} ({r.steps} steps)")


RECIPES = RecipesCommand()


def recipe_entry(name: str, path: Path) -> RecipeEntry:
    """A recipe's name, description and number of steps, read from its file as written.

    Raises:
        MotorlabError: the file cannot be read or is not TOML.
    """
    data = read_text_file(Path(path), tomllib.loads, "TOML", "give a recipe file (motorlab recipes lists the bundled).")
    steps = data.get("steps")
    return RecipeEntry(str(data.get("name", name)), str(data.get("description", "")),
                       len(steps) if isinstance(steps, list) else 0)


def field_line(model: type[Settings], name: str) -> str:
    """A recipe field as `--kinds` lists it: its default, or that it is required."""
    info = model.model_fields.get(name)
    if info is None:
        return name  # the flat env settings (env, delay, history, ...) and seeds
    default = info.get_default(call_default_factory=True)
    return f"{name} = {default!r}" if not info.is_required() else f"{name} (required)"
