"""The bases of every step's settings and summary. One pydantic model per step kind holds its
defaults, validation and help text, so the CLI, recipes, sweeps and the Python API agree on
them; another types the summary.json its run writes."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, ClassVar, Union, get_args, get_origin

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import InitErrorDetails, PydanticCustomError, PydanticUndefined

from motorlab.errors import MotorlabError

Loc = tuple[str | int, ...]

# The largest seed a setting takes: numpy's legacy seeds and SB3's stop at 2**32 - 1, and episode seeds
# (seed + i) must stay far from int64's end, where numpy's arithmetic overflows
MAX_SEED = 2**32 - 1
MAX_SEEDS = 10_000  # seeds in one sweep or search: far beyond any study; a typo such as --seeds 1000000 should fail, not plan for hours
# Integers past int64 fit no array, tensor or C library motorlab hands them to
MAX_INT = 2**63 - 1


class StrictModel(BaseModel):
    """A pydantic model that refuses unknown fields, and true/false where a number belongs.

    Pydantic's lax mode reads `true` as 1 for an int or float field, so a recipe's `episodes =
    true` (or `--set episodes=true`) would run one episode. Its strict mode would also refuse the
    conversions settings rely on (`"3"` from a command line, `1e3` from TOML as 1000), so only
    booleans are refused, before pydantic converts anything: in this model's fields and in those of
    the plain pydantic models nested in it (a StrictModel nested in it checks its own).

    Numbers must be finite (pydantic's `allow_inf_nan=False` for its own float fields, and
    `_finite_numbers` for floats anywhere in it, tables of keyword arguments and nested models
    included): NaN and infinity have no TOML form, so config.toml could not repeat the run, and no
    setting of motorlab's means anything by them."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

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

    @model_validator(mode="after")
    def _finite_numbers(self):
        found = unusable_number(self)
        if found is not None:
            loc, inner, value, why = found
            # a number inside a table or list (--set gamma=nan, --env-arg x=inf) is named by its field,
            # the option, with its place inside said in the message
            text = f"{'.'.join(map(str, inner))} = {value}: {why}" if inner else why
            error = PydanticCustomError("unusable_number", "{text}", {"text": text})
            given: Any = self if inner else value  # inside a table or list: the option's whole value
            for name in loc if inner else ():
                given = getattr(given, str(name))
            raise ValidationError.from_exception_data(type(self).__name__, [InitErrorDetails(
                type=error, loc=loc, input=given)])
        return self


def unusable_number(value: Any, loc: Loc = (), inner: Loc = ()) -> tuple[Loc, Loc, Any, str] | None:
    """Where `value` (validated settings, however nested: models, tables, lists) holds what no run can
    use or config.toml cannot record: (the field's place, the value's place inside that field's value,
    the value, why). NaN or infinity; an integer past int64; inside a table or list (keyword arguments
    for an env or an algorithm), a value TOML has no form for (none/null, a Python object). None: nowhere."""
    if isinstance(value, float) and not math.isfinite(value) or _non_finite_text(value, inner):
        return loc, inner, value, "give a finite number (NaN and infinity cannot be written to config.toml, nor used)"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INT:
        return loc, inner, value, f"give a number of at most {MAX_INT:,} (64 bits)"
    if isinstance(value, BaseModel) and not inner:  # a model's fields are places of their own
        found = ((unusable_number(getattr(value, n, None), (*loc, n))) for n in type(value).model_fields)
    elif isinstance(value, Mapping):
        found = (unusable_number(v, loc, (*inner, k)) for k, v in value.items())
    elif isinstance(value, (list, tuple)):
        found = (unusable_number(v, loc, (*inner, i)) for i, v in enumerate(value))
    elif inner and not isinstance(value, (str, int, float, Path)):  # bool is an int; a path is written as text
        return loc, inner, value, ("give text, a number, true/false, a list or a table (config.toml records it: "
                                   "TOML has no null, leave the key out for its default)")
    else:
        return None
    return next((f for f in found if f is not None), None)


def _non_finite_text(value: Any, inner: Loc) -> bool:
    """"nan" or "inf" as text inside a table (`--set gamma=inf`, `--env-arg x=nan` from a command line):
    the algorithm or env reading it as a number would get NaN or infinity."""
    if not (isinstance(value, str) and inner and isinstance(inner[0], str)):
        return False
    try:
        return not math.isfinite(float(value))
    except ValueError:
        return False


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
        """What config.toml records of these settings: plain values (a path as text), which read
        back give the same settings."""
        return self.model_dump(mode="json")


@dataclass(frozen=True)
class UserCode:
    """A field's mark (`Annotated[str, UserCode(check)]`, or on a list of them): its value names the
    user's code or what that code registers (MODULE:FUNCTION, FILE.py:FUNCTION, a MODULE:EnvId env
    id), which `check(value)` finds or refuses with a MotorlabError. `check_user_code` calls it for
    every field so marked, of any kind, nested models' too, when settings are checked before any work
    (a recipe's validation, `motorlab run --check`): a new kind's field is checked by being marked."""

    check: Callable[[str], None]


def user_code(settings: BaseModel, loc: Loc = ()) -> Iterator[tuple[Loc, str, UserCode]]:
    """Every value of `settings` (nested models included) that names the user's code: (the field's
    place, the value, its mark); each item of a marked list."""
    for name, info in type(settings).model_fields.items():
        value = getattr(settings, name, None)
        mark = next((m for m in info.metadata if isinstance(m, UserCode)), None)
        if mark is not None:
            yield from (((*loc, name), item, mark) for item in (value if isinstance(value, (list, tuple)) else [value])
                        if isinstance(item, str))
        elif isinstance(value, BaseModel):
            yield from user_code(value, (*loc, name))


def check_user_code(settings: BaseModel) -> None:
    """Find the code every marked field of `settings` names (see UserCode); a recipe's "@step"
    reference names a step's output, not code, and is left to the study.

    Raises:
        MotorlabError: one line naming the field and what is missing (the module, the function).
    """
    for loc, value, mark in user_code(settings):
        if value.startswith("@"):
            continue
        try:
            mark.check(value)
        except MotorlabError as e:
            field = ".".join(map(str, loc))
            text = str(e)
            raise MotorlabError(text if field in text else f"{field}: {text}") from None


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
