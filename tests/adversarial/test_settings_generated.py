"""Generated settings (issue 52): every field of every command's settings model, given values drawn
from its annotation's hostile neighbours (NaN, infinities, huge, negative and zero numbers, wrong
types, empty and unicode text), either makes valid settings or is one `MotorlabError` line naming
the option; never another exception. Valid settings written to config.toml (as a run writes them)
and read back are the same settings, so `--config` repeats the run.

Bounded in `make test`; MOTORLAB_SETTINGS_EXAMPLES=200 tries more per field.
"""

from __future__ import annotations

import math
import os
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from motorlab.envs import ENV_KEYS, EnvConfig
from motorlab.errors import MotorlabError
from motorlab.registry import COMMANDS
from motorlab.runs import write_toml
from motorlab.settings import MAX_INT, MAX_SEED

pytestmark = pytest.mark.fast

GEN = settings(max_examples=int(os.environ.get("MOTORLAB_SETTINGS_EXAMPLES", 12)), deadline=None,
               derandomize=True, database=None,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

# A value for each required field, so that the field under test is the one judged
REQUIRED = {
    "policy": "random", "run": "runs/train", "activations": "runs/collect", "runs": ["runs/train"],
    "envs": ["InvertedPendulum-v5"], "policies": ["random"], "vary": ["delay=0,0.1"], "groups": {"a": ["runs/train"]},
    "env": "InvertedPendulum-v5", "transitions": "runs/collect", "model": "runs/fit", "source": "runs/train",
    "paths": ["runs/train"], "run_dir": "runs/train", "folder": "sk", "out": "sar.npz", "sar": "sar.npz",
    "recipe": "pendulum", "target": "evaluate random", "space": ["episodes=int:1,9"],  # sweep, tune
    "file": "emg.csv", "rate": 2000.0,  # synergies import-emg
    "a": "runs/fit", "b": "runs/fit-b",  # synergies compare
}
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf, "nan", "inf", "-inf", "NaN", "1e999"])
HUGE = st.sampled_from([MAX_SEED + 1, MAX_INT + 1, 10**30, -(10**30), 1e308, -1e308, 2**64])
SMALL = st.one_of(st.sampled_from([0, -1, 0.0, -0.0, 1e-320, 1, 2]), st.integers(-10, 10),
                  st.floats(-10, 10, allow_nan=False))
TEXT = st.one_of(st.sampled_from(["", " ", "é", "日本", "a\x00b", "0..nan", "1..inf", "-1..2", "nan..1", "@step",
                                  "module:fn", "linear:nan,0"]),
                 st.text(max_size=8))
WRONG = st.one_of(st.booleans(), st.none(), st.lists(st.one_of(SMALL, NON_FINITE, TEXT), max_size=3),
                  st.dictionaries(st.text(max_size=4), st.one_of(SMALL, NON_FINITE, HUGE), max_size=2))
HOSTILE = st.one_of(NON_FINITE, HUGE, SMALL, TEXT, WRONG)


def _members(annotation: Any) -> tuple[Any, ...]:
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return tuple(m for a in typing.get_args(annotation) for m in _members(a))
    return (annotation,)


def values_for(annotation: Any) -> st.SearchStrategy:
    """Hostile values near what the annotation takes: its own items made hostile, for lists and tables."""
    for member in _members(annotation):
        origin, args = typing.get_origin(member), typing.get_args(member)
        if origin is list and args:
            return st.one_of(HOSTILE, st.lists(HOSTILE, max_size=3))
        if origin is dict and len(args) == 2:
            return st.one_of(HOSTILE, st.dictionaries(st.text(max_size=6), st.one_of(HOSTILE, st.lists(HOSTILE, max_size=2)),
                                                      max_size=3))
        if isinstance(member, type) and issubclass(member, BaseModel):
            return st.one_of(HOSTILE, st.fixed_dictionaries({}, optional={
                n: values_for(i.annotation) for n, i in member.model_fields.items()}))
    return HOSTILE


def _fields(command) -> list[tuple[str, Any]]:
    """(name, annotation) of every field a command takes, the flat env settings among them."""
    model = command.settings
    own = [(n, i.annotation) for n, i in model.model_fields.items()]
    flat = [(k, EnvConfig.model_fields[f].annotation) for k, f in ENV_KEYS.items()
            if k in model.aliases and k not in model.model_fields]
    return own + flat


CASES = [(name, field, annotation) for name, command in COMMANDS.items() for field, annotation in _fields(command)]


# The words the disturbance ranges' own errors name their options by (motorlab.envs: EnvConfig's parsers)
HUMAN = ("delay time constant", "latency", "observation noise", "obs noise", "action noise", "push force",
         "push interval", "motor noise")


def _spellings(command, field: str) -> set[str]:
    """How a one-line error may name the option: its field name, its CLI spellings, its env field's."""
    names = {field, ENV_KEYS.get(field, field), *(f.lstrip("-") for f in command.flags.get(field, ()))}
    return names | {n.replace("_", "-") for n in names} | set(HUMAN)


def _base(command, field: str) -> dict[str, Any]:
    fields = command.settings.model_fields
    required = {n for n, i in fields.items() if i.is_required()} | ({"env"} & set(fields))  # an env: its id
    return {n: REQUIRED[n] for n in required if n != field}


def test_every_required_field_has_a_value():
    """The cases below judge one field at a time: every command's other required fields are given."""
    for command in COMMANDS.values():
        command.make(**_base(command, ""))  # valid: raises nothing


def assert_round_trip(command, made, tmp: Path) -> None:
    """config.toml of `made`, read back, validates to the same settings."""
    path = tmp / "config.toml"
    write_toml(path, made.config())
    again = command.validate(tomllib.loads(path.read_text()))
    assert again.model_dump() == made.model_dump(), (made.config(), path.read_text())


@pytest.mark.parametrize(("command", "field", "annotation"), CASES, ids=[f"{c}-{f}" for c, f, _ in CASES])
@GEN
@given(data=st.data())
def test_generated_values_give_settings_or_one_line(command, field, annotation, data, tmp_path):
    cmd = COMMANDS[command]
    value = data.draw(values_for(annotation), label=field)
    try:
        made = cmd.make(**_base(cmd, field), **{field: value})
    except MotorlabError as e:
        text = str(e)
        assert "\n" not in text.strip(), text
        assert any(s in text for s in _spellings(cmd, field)) or _names_a_nested_field(cmd, text), text
        return
    assert_round_trip(cmd, made, tmp_path)


def _names_a_nested_field(command, text: str) -> bool:
    """An error in a nested model's field (env.delay, lqr.ridge) may name that field alone."""
    nested = [m for info in command.settings.model_fields.values() for m in _members(info.annotation)
              if isinstance(m, type) and issubclass(m, BaseModel)]
    return any(f in text or f.replace("_", "-") in text for m in nested for f in m.model_fields)


# ---- the listed defects -------------------------------------------------------------------------

@pytest.mark.parametrize("value", ["nan", "inf", "-inf", math.nan, math.inf])
def test_solve_return_nan_is_refused(value):
    """`--solve-return nan` was accepted, and config.toml (no NaN in TOML) then did not repeat the run."""
    with pytest.raises(MotorlabError, match="--solve-return"):
        COMMANDS["train"].make(env="InvertedPendulum-v5", solve_return=value)


@pytest.mark.parametrize(("fields", "named"), [
    ({"hyperparams": {"gamma": math.nan}}, "gamma"),
    ({"hyperparams": {"gamma": "inf"}}, "gamma"),  # text from --set gamma=inf: SB3 would read it as a number
    ({"hyperparams": {"policy_kwargs": {"net_arch": [64, math.inf]}}}, "net_arch"),
    ({"env_kwargs": {"x": math.inf}}, "x = inf"),
    ({"lqr": {"ridge": "inf"}}, "ridge"),
    ({"lr": "linear:nan,0"}, "learning-rate"),
    ({"delay": "0..nan"}, "delay"),
    ({"obs_noise": [0.1, math.nan]}, "--obs-noise"),
    ({"seed": MAX_SEED + 1}, "--seed"),
    ({"seed": 10**30}, "--seed"),
    ({"preset": math.nan}, "--preset"),
    ({"preset_file": 1.5}, "--preset-file"),
])
def test_hidden_numbers_are_finite(fields, named):
    """Numbers inside tables and lists (SB3 keyword arguments, env kwargs, nested models, schedules,
    ranges) are judged like the fields' own: one line naming where."""
    with pytest.raises(MotorlabError) as e:
        COMMANDS["train"].make(env="InvertedPendulum-v5", **fields)
    assert named in str(e.value) and "\n" not in str(e.value)


def test_a_run_config_repeats_the_run(tmp_path):
    """Settings with every kind of value (tables, lists, ranges, nested models) survive config.toml."""
    train = COMMANDS["train"]
    made = train.make(env="InvertedPendulum-v5", solve_return=-1e300, delay="0.05..0.3", obs_noise=[0.0, 0.01],
                      hyperparams={"gamma": 0.99, "policy_kwargs": {"net_arch": [8, 8]}}, seed=MAX_SEED,
                      env_kwargs={"reset_noise_scale": 0.01}, lqr={"ridge": 0.5})
    assert_round_trip(train, made, tmp_path)
