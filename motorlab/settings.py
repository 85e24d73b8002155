"""The bases of every step's settings and summary. One pydantic model per step kind holds its
defaults, validation and help text, so the CLI, recipes, sweeps and the Python API agree on
them; another types the summary.json its run writes."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, ClassVar, Union, get_args, get_origin

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError, PydanticUndefined

Loc = tuple[str | int, ...]


class StrictModel(BaseModel):
    """A pydantic model that refuses unknown fields, and true/false where a number belongs.

    Pydantic's lax mode reads `true` as 1 for an int or float field, so a recipe's `episodes =
    true` (or `--set episodes=true`) would run one episode. Its strict mode would also refuse the
    conversions settings rely on (`"3"` from a command line, `1e3` from TOML as 1000), so only
    booleans are refused, before pydantic converts anything: in this model's fields and in those of
    the plain pydantic models nested in it (a StrictModel nested in it checks its own)."""

    model_config = ConfigDict(extra="forbid")

    @model_validator(mode="before")
    @classmethod
    def _refuse_bool_numbers(cls, data: Any) -> Any:
        # a model validator, not a field one: a subclass's own "before" field validators (e.g. a
        # delay's "LOW..HIGH" parser, which reads true as 1.0) run before a base's field validators
        found = bool_for_number(cls, data) if isinstance(data, Mapping) else None
        if found is not None:
            loc, what = found
            error = PydanticCustomError("bool_not_number", "give {what}, not true/false", {"what": what})
            # raised inside validation, pydantic puts the outer fields' names in front of `loc`
            raise ValidationError.from_exception_data(cls.__name__, [InitErrorDetails(
                type=error, loc=loc, input=_at(data, loc))])
        return data


def bool_for_number(model: type[BaseModel], data: Mapping[str, Any], loc: Loc = ()) -> tuple[Loc, str] | None:
    """Where `data` (a model's input) gives true/false to a field that takes a number, and what that
    field takes ("a whole number", "a number"); None when it nowhere does."""
    for name, info in model.model_fields.items():
        key = info.alias or name
        if key in data:
            found = _bool_where_number(info.annotation, data[key], (*loc, key))
            if found is not None:
                return found
    return None


def _members(annotation: Any) -> tuple[Any, ...]:
    """The types an annotation admits: a union's members (None among them), Annotated's type."""
    origin = get_origin(annotation)
    if origin is Annotated:
        return _members(get_args(annotation)[0])
    if origin in (Union, UnionType):
        return tuple(m for arg in get_args(annotation) for m in _members(arg))
    return (annotation,)


def _bool_where_number(annotation: Any, value: Any, loc: Loc) -> tuple[Loc, str] | None:
    members = _members(annotation)
    if isinstance(value, bool):
        if any(m in (bool, Any, object) for m in members):
            return None
        if int in members:
            return loc, "a whole number"
        if float in members:
            return loc, "a number"
        return None  # a type pydantic refuses true for by itself (text, a choice)
    for member in members:
        origin, args = get_origin(member), get_args(member)
        if isinstance(value, Mapping):
            if isinstance(member, type) and issubclass(member, BaseModel) and not issubclass(member, StrictModel):
                found = bool_for_number(member, value, loc)
            elif origin in (dict, Mapping) and len(args) == 2:
                found = _items(_bool_where_number(args[1], v, loc) for v in value.values())
            else:
                continue
        elif isinstance(value, (list, tuple)) and origin in (list, tuple, set, frozenset) and args:
            fixed = origin is tuple and args[-1] is not Ellipsis  # tuple[int, str]: one type per place
            items = args if fixed else args[:1] * len(value)
            found = _items(_bool_where_number(t, v, loc) for t, v in zip(items, value))
        else:
            continue
        if found is not None:
            return found
    return None


def _items(found: Iterable[tuple[Loc, str] | None]) -> tuple[Loc, str] | None:
    """The first item of a list or table given true/false, named by its field (the option): "numbers"."""
    first = next((f for f in found if f is not None), None)
    return first and (first[0], _PLURAL.get(first[1], first[1]))


_PLURAL = {"a whole number": "whole numbers", "a number": "numbers"}


def _at(data: Any, loc: Loc) -> Any:
    for key in loc:
        data = data[key]
    return data


class Settings(StrictModel):
    """A step's settings. Field defaults and descriptions are the defaults and help of the CLI
    options and recipe fields that set them."""

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
