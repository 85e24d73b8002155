"""The Python API's door: a user's mistake raises a `MotorlabError`, and nothing else.

Each public function of `motorlab.api` is wrapped by `api_function`, which checks a call before
the function runs and turns what its settings and the system refuse into motorlab's errors:

- a call that does not fit the signature (an unknown keyword, a missing argument) and an argument
  of the wrong type (`robustness(vary=5)`) raise `ArgumentError` (a TypeError too), naming it;
- a pydantic ValidationError that a settings model raised is a `SettingsError` (a ValueError too);
- an OSError the system raised about a path (full disk, name too long, symlink loop, ...) is the
  `StorageError` the CLI prints, the same line (`StorageError.of`);
- anything else is a bug, and keeps its traceback.

Types are checked against the annotations with pydantic, in its lax mode (a tuple where a list
is expected is fine), and the function gets the values pydantic made: what its annotations promise.
"""

from __future__ import annotations

import functools
import inspect
import typing
from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import ConfigDict, TypeAdapter, ValidationError

from motorlab.command import option_error
from motorlab.errors import ArgumentError, MotorlabError, SettingsError, StorageError

F = TypeVar("F", bound=Callable[..., Any])
_CONFIG = ConfigDict(arbitrary_types_allowed=True)
PUBLIC = {"motorlab.api.synergies": "motorlab.synergies", "motorlab.api.dynamics": "motorlab.dynamics"}


def api_function(fn: F) -> F:
    """`fn`, raising only MotorlabError subclasses for a caller's mistakes (see the module's doc)."""
    signature = inspect.signature(fn)
    name = f"{PUBLIC.get(fn.__module__, 'motorlab')}.{fn.__qualname__}"  # as a user calls it

    @functools.wraps(fn)
    def checked(*args: Any, **kwargs: Any) -> Any:
        try:
            bound = signature.bind(*args, **kwargs)
        except TypeError as e:
            raise ArgumentError(f"{name}(): {e}; see help({name}).") from None
        _check_types(fn, name, bound)
        try:
            return fn(*bound.args, **bound.kwargs)
        except MotorlabError:
            raise
        except ValidationError as e:
            raise SettingsError(f"{name}(): {option_error(e)}.") from None
        except (OSError, RuntimeError) as e:  # RuntimeError: pathlib's symlink loop before Python 3.13
            if (known := StorageError.of(e)) is None:
                raise
            raise known from e

    return typing.cast(F, checked)


def _check_types(fn: Callable[..., Any], name: str, bound: inspect.BoundArguments) -> None:
    """Each argument given against its annotation (those that cannot be resolved are not checked), and
    replaced by the value pydantic made of it (a tuple where a list is expected is that list): the
    function gets what its annotations promise."""
    adapters = _adapters(fn)
    for arg, value in bound.arguments.items():
        adapter = adapters.get(arg)
        if adapter is None:
            continue
        try:
            if isinstance(value, (bytes, bytearray)):  # pydantic's lax str takes bytes; no argument here does
                raise ValidationError.from_exception_data("bytes", [{"type": "string_type", "input": value}])
            bound.arguments[arg] = adapter.validate_python(value)
        except ValidationError as e:
            shown = repr(value) if len(repr(value)) <= 60 else f"a {type(value).__name__}"
            expected = fn.__annotations__[arg]
            expected = expected if isinstance(expected, str) else getattr(expected, "__name__", str(expected))
            errors = e.errors()
            why = f" ({errors[0]['msg'][:1].lower()}{errors[0]['msg'][1:]})" if len(errors) == 1 else ""
            raise ArgumentError(f"{name}(): {arg}={shown}: expected {expected}{why}; see help({name}).") from None


@functools.cache
def _adapters(fn: Callable[..., Any]) -> dict[str, TypeAdapter]:
    """A pydantic adapter per annotated parameter of `fn` (not *args, **kwargs), made once, on first use
    (a name an annotation uses may be defined further down its module)."""
    adapters = {}
    for param in inspect.signature(fn).parameters.values():
        if param.kind in (param.VAR_POSITIONAL, param.VAR_KEYWORD) or param.name not in fn.__annotations__:
            continue
        try:
            hint = fn.__annotations__[param.name]
            if isinstance(hint, str):  # `from __future__ import annotations`
                hint = eval(hint, fn.__globals__)  # noqa: S307 - the module's own annotation
            adapters[param.name] = TypeAdapter(hint, config=_CONFIG)
        except Exception:  # noqa: BLE001, S112 - a name only a type checker sees, or a type pydantic cannot check
            continue
    return adapters
