"""A command's settings model as a command line: one Click command per `Command`, nothing typed twice.

Every field of a command's settings model is an option named after it (`n_synergies` →
`--n-synergies`), with the field's description (and default) as its help; the fields the command
names in `arguments` are positional. The flat env settings of a model that builds an env
(`EnvSettings.aliases`: env, delay, history, --env-arg, the disturbances) are options too, with
EnvConfig's help. The invocation model (command.Invocation: --out, --overwrite, --track, ...)
adds its fields the same way. The values given become keyword arguments of `Command.how` (the
invocation) and `Command.make` (the settings, under what the invocation brings: train's --config):
the model checks them, so a sweep's target, a script and the command line are judged alike.

Plain Click rather than Typer: a command is built from data here, not from a function's signature,
and Click's help never cuts an option's name (at 80 columns a long one moves its help to the next
line).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from types import UnionType
from typing import Any, Callable, Union, get_args, get_origin

import click
from pydantic import BaseModel
from pydantic.fields import FieldInfo

from motorlab.command import Command
from motorlab.errors import MotorlabError
from motorlab.settings import help_text

HOW = "how__"  # prefix of the invocation's parameters (a settings field may share a name: mbrl's resume)
ENV_ARG = "env_kwargs"  # the alias of EnvConfig.kwargs, given as --env-arg KEY=VALUE
DEFAULT_FLAGS = {ENV_ARG: ("--env-arg",)}


@dataclass(frozen=True)
class Given:
    """A command line read into its command's terms: settings fields (flat, as given) and invocation options."""

    fields: dict[str, Any] = field(default_factory=dict)
    how: dict[str, Any] = field(default_factory=dict)


def _base(annotation: Any) -> Any:
    """How the command line gives a field's value: the type inside Optional[...]; of a union of containers,
    its first (`grid: list[str] | dict[str, list[Any]]`: KEY=V1,V2 items here, a dict from Python); any other
    union is text its settings model reads (`obs_noise: float | str | list[float]`: 0.05, 0..0.1)."""
    args = [a for a in get_args(annotation) if a is not type(None)]
    if get_origin(annotation) not in (Union, UnionType) or not args:
        return annotation
    if len(args) == 1 or all(get_origin(a) in (list, tuple, dict) for a in args):
        return args[0]
    return annotation


def _is_bool(annotation: Any) -> bool:
    return _base(annotation) is bool


def value_kind(annotation: Any) -> str:
    """How a field's value is given: flag, numbers (64,64), many (repeatable), pairs (KEY=VALUE), int, float, text."""
    base = _base(annotation)
    origin = get_origin(base)
    if base is bool:
        return "flag"
    if origin is list and get_args(base) and get_args(base)[0] in (int, float):
        return "numbers"
    if origin in (list, tuple):
        return "many"
    if origin is dict or base is dict:
        return "pairs"
    if base is int:
        return "int"
    if base is float:
        return "float"
    return "text"  # text, paths, choices, unions: the model converts and checks them


def _option_names(cmd: Command, name: str) -> tuple[str, ...]:
    return cmd.flags.get(name) or DEFAULT_FLAGS.get(name) or ("--" + name.replace("_", "-"),)


def _parameter(cmd: Command, name: str, info: FieldInfo, text: str, param: str | None = None) -> click.Parameter:
    """One Click parameter for the field `name` (`param`: its Python name, default the field's)."""
    param = param or name
    kind = value_kind(info.annotation)
    if name in cmd.arguments:
        variadic = kind == "many"
        return click.Argument([param], nargs=-1 if variadic else 1, required=info.is_required())
    names = _option_names(cmd, name)
    if kind == "flag":  # absent: the model's default (a preset's value survives an unset switch)
        switch = names[0] if "/" in names[0] else f"{names[0]}/--no-{names[0][2:]}"  # flags may name the off switch
        return click.Option([param, switch, *names[1:]], default=None, help=text)
    types = {"int": click.INT, "float": click.FLOAT}
    return click.Option([param, *names], type=types.get(kind, click.STRING), multiple=kind in ("many", "pairs"),
                        required=info.is_required() and kind not in ("many", "pairs"), default=None,
                        help=text + (" Repeatable." if kind in ("many", "pairs") else ""),
                        metavar="KEY=VALUE" if kind == "pairs" else None)


def _env_fields(settings: type[BaseModel]) -> dict[str, tuple[FieldInfo, str]]:
    """The flat env settings a model takes (alias -> EnvConfig's field and its help), if it builds an env."""
    from motorlab.envs import ENV_KEYS, EnvConfig  # the domain's env model; imported when a command is built

    aliases = getattr(settings, "aliases", frozenset())
    return {alias: (EnvConfig.model_fields[ENV_KEYS[alias]], help_text(EnvConfig, ENV_KEYS[alias]))
            for alias in ENV_KEYS if alias in aliases}


def parameters(cmd: Command) -> list[click.Parameter]:
    """The command's parameters: its arguments, its settings' options (a model's own fields first,
    then those of the bases it shares with other commands), then the invocation's."""
    model = cmd.settings
    own = list(model.__dict__.get("__annotations__", {}))
    fields = sorted(((n, i) for n, i in model.model_fields.items() if _on_command_line(i)),
                    key=lambda item: own.index(item[0]) if item[0] in own else len(own))
    env = _env_fields(model) if "env" in model.model_fields and _env_fields(model) else {}
    params: list[click.Parameter] = []
    for name, info in fields:
        if name == "env" and env:
            for alias, (env_info, text) in env.items():
                if alias == "env" and info.is_required():  # a kind that needs the env id: no default id
                    env_info = FieldInfo(annotation=str)
                params.append(_parameter(cmd, alias, env_info, text))
            continue
        params.append(_parameter(cmd, name, info, help_text(model, name)))
    for name, info in cmd.invocation.model_fields.items():
        text = cmd.out_help if name == "out" and cmd.out_help else help_text(cmd.invocation, name)
        if name == "out" and cmd.out_required:
            info = FieldInfo(annotation=Path)  # required
        params.append(_parameter(cmd, name, info, text, param=HOW + name))
    arguments = {p.name: p for p in params if isinstance(p, click.Argument)}
    return [arguments[a] for a in cmd.arguments if a in arguments] + [
        p for p in params if not isinstance(p, click.Argument)]


def _on_command_line(info: FieldInfo) -> bool:
    extra = info.json_schema_extra
    return not (isinstance(extra, dict) and extra.get("cli") is False)


def given(cmd: Command, values: dict[str, Any]) -> Given:
    """The values Click parsed as the command's fields and invocation options (those given only)."""
    kinds = {**{n: value_kind(i.annotation) for n, i in cmd.settings.model_fields.items()},
             **{a: value_kind(i.annotation) for a, (i, _) in _env_fields(cmd.settings).items()},
             **{HOW + n: value_kind(i.annotation) for n, i in cmd.invocation.model_fields.items()}}
    fields, how = {}, {}
    for name, value in values.items():
        if value is None or (isinstance(value, tuple) and not value):
            continue
        kind = kinds.get(name, "text")
        flag = _option_names(cmd, name.removeprefix(HOW))[0].split("/")[0]
        if kind == "numbers":
            value = numbers(value, flag)
        elif kind == "pairs":
            value = pairs(value, flag)
        elif kind == "many":
            value = list(value)
        if name.startswith(HOW):
            how[name.removeprefix(HOW)] = value
        else:
            fields[name] = value
    return Given(fields, how)


def numbers(text: str, flag: str) -> list[float]:
    """"64,64" as numbers (the model makes them whole where the field wants it)."""
    try:
        return [json.loads(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise MotorlabError(f"{flag} {text!r}: write numbers separated by commas, e.g. 64,64.") from None


EXAMPLES = {"--env-arg": "time_limit=5", "--set": "n_steps=1024", "--group": "SAR-RL=runs/a,runs/b"}
FORMS = {"--group": "LABEL=RUN_DIR[,RUN_DIR...]"}  # what KEY and VALUE are, where it is not plain


def pairs(items: tuple[str, ...] | list[str], flag: str) -> dict[str, Any]:
    """KEY=VALUE items, each VALUE read as JSON where it is JSON, else as text."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise MotorlabError(f"{flag} {item!r}: write {FORMS.get(flag, 'KEY=VALUE')}, e.g. {flag} "
                                f"{EXAMPLES.get(flag, 'KEY=1')}.")
        out[key] = json_or_text(value)
    return out


def json_or_text(text: str) -> Any:
    """A VALUE as --set and --env-arg read it: JSON where it is JSON, else the text itself."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def epilog(cmd: Command) -> str | None:
    """The command's examples as its help's epilog (each on its own, unwrapped line)."""
    if not cmd.examples:
        return None
    return "Examples:\n\n" + "\n".join(f"\b\n  {line}" for line in cmd.examples)


def click_command(cmd: Command, callback: Callable[[Command, Given], None]) -> click.Command:
    """The Click command of `cmd` (named by the last word of its `command`); `callback` gets what was given."""
    text = cmd.help()
    short = text.splitlines()[0] if text else ""
    return click.Command(cmd.command.split()[-1], params=parameters(cmd), help=text, short_help=short,
                         epilog=epilog(cmd), callback=lambda **values: callback(cmd, given(cmd, values)),
                         context_settings={"max_content_width": 120})


def command_line(cmd: Command, fields: dict[str, Any]) -> list[str]:
    """The words after `motorlab <command>` that give `fields` (flat, as `Given.fields` holds them, the
    flat env settings included): what `parse` reads back into the same fields. For records and
    reproduce lines of settings made in Python (a sweep's or search's target)."""
    kinds = {**{n: value_kind(i.annotation) for n, i in cmd.settings.model_fields.items()},
             **{a: value_kind(i.annotation) for a, (i, _) in _env_fields(cmd.settings).items()}}
    positional = [_text(fields[a]) for a in cmd.arguments if a in fields]
    words: list[str] = []
    for name, value in fields.items():
        if name in cmd.arguments or value is None:
            continue
        names = _option_names(cmd, name)
        flag = names[0].split("/")[0]
        kind = kinds.get(name, "text")
        if kind == "flag":
            off = names[0].split("/")[1] if "/" in names[0] else f"--no-{flag[2:]}"
            words.append(flag if value else off)
        elif kind == "numbers":
            words += [flag, ",".join(json.dumps(v) for v in value)]
        elif kind == "many":
            for item in value:
                words += [flag, _text(item)]
        elif kind == "pairs":
            for key, item in value.items():
                words += [flag, f"{key}={_pair_value(item)}"]
        else:
            words += [flag, _text(value)]
    return positional + words


def _text(value: Any) -> str:
    """A value as an option gives it: text as it is, a float exactly (repr), others as str."""
    if isinstance(value, float):
        return repr(value)
    return value if isinstance(value, str) else str(value)


def _pair_value(value: Any) -> str:
    """A KEY=VALUE item's VALUE that `json_or_text` reads back as `value`: text that would read as JSON
    ("1", "true") and every other value as JSON."""
    if isinstance(value, str) and not _reads_as_json(value):
        return value
    return json.dumps(value)


def _reads_as_json(text: str) -> bool:
    try:
        json.loads(text)
    except json.JSONDecodeError:
        return False
    return True


def parse(cmd: Command, words: list[str], where: str) -> Given:
    """Read (not run) a command line of `cmd`'s (its words after the command's name).

    Raises:
        MotorlabError: what the parser says (an unknown option, a missing argument), after `where`.
    """
    command = click_command(cmd, lambda *_: None)
    try:
        ctx = command.make_context(f"motorlab {cmd.command}", list(words), resilient_parsing=False)
    except click.ClickException as e:
        raise MotorlabError(f"{where}: {e.format_message()}") from None
    return given(cmd, ctx.params)
