"""Sweep and tune targets read once, where they enter: the command line's text or Python's values, to the
same typed target; the trials a sweep plans from either are the same, and Python's numbers stay numbers."""

from __future__ import annotations

import math
import shlex
import tomllib
from pathlib import Path

import optuna
import pytest
from hypothesis import example, given
from hypothesis import settings as settings_
from hypothesis import strategies as st

import motorlab
from motorlab.commandline import command_line, parse
from motorlab.errors import MotorlabError
from motorlab.kinds import for_command
from motorlab.sweeps.sweep import plan
from motorlab.sweeps.sweep_command import SWEEP
from motorlab.sweeps.targets import RecipeTarget, StepTarget, read_target
from motorlab.tuning.space import parse_space
from motorlab.tuning.tune_command import TUNE
from tests.helpers import ENV_ID

finite = st.floats(min_value=1e-6, max_value=1.0, allow_nan=False, allow_infinity=False)
word = st.text(st.characters(codec="ascii", categories=("L", "N")), min_size=1, max_size=8)
# train's settings of every way an option is given: text, a number, a switch, a list, KEY=VALUE pairs
TRAIN_FIELDS = st.fixed_dictionaries({"env": st.just(ENV_ID)}, optional={
    "algo": st.sampled_from(["ppo", "sac", "td3"]),
    "timesteps": st.integers(1, 10**7),
    "lr": finite.map(repr),
    "until_solved": st.booleans(),
    "normalize": st.booleans(),
    "minutes": finite,
    "n_envs": st.integers(1, 8),
    "delay": st.floats(0, 0.5, allow_nan=False),
    "hyperparams": st.dictionaries(st.sampled_from(["gamma", "n_steps", "ent_coef", "note"]),
                                   st.one_of(finite, st.integers(1, 4096), word, st.just("1"), st.just("true")),
                                   max_size=3),
})


@settings_(max_examples=60, deadline=None)
@given(fields=TRAIN_FIELDS)
@example(fields={"env": ENV_ID, "hyperparams": {"gamma": "INF"}})  # once found by the generated inputs
def test_a_command_line_written_from_fields_reads_back_as_those_fields(fields):
    """`command_line` (a Python-made target's record and reproduce line) is what `parse` reads back into the
    same settings: text that would read as JSON ("1", "true") stays text, numbers stay numbers (a field
    the command line gives as text, like --delay's 0.1 or 0..0.2, is read by its settings model)."""
    kind = for_command("train")
    words = command_line(kind, fields)
    read = parse(kind, shlex.split(shlex.join(words)), "test").fields
    assert read.keys() == {k for k, v in fields.items() if v != {}}
    assert _made(kind, read) == _made(kind, fields)


def _made(kind, fields) -> dict | str:
    """The settings these fields make, or the one line that refuses them (a generated word may be a
    number's name: gamma = "INF" reads as infinity, refused alike from the command line and from Python)."""
    try:
        return kind.make(**fields).model_dump()
    except MotorlabError as e:
        return f"refused: {e}"


def _trial_settings(target, grid):
    return {t["name"]: t["job"]["settings"] for t in plan(target, [0, 1], grid, Path("/nonexistent/sweep"))[0]}


@settings_(max_examples=25, deadline=None)
@given(lrs=st.lists(finite, min_size=1, max_size=3, unique=True), n_envs=st.lists(st.integers(1, 4), min_size=1,
                                                                                 max_size=2, unique=True))
def test_pythons_grid_and_the_command_lines_plan_the_same_trials(lrs, n_envs):
    """The same settings given as Python values (a `step` target, a dict grid of numbers) and as the command
    line's text plan trials with the same settings; Python's are numbers, never turned into text and back."""
    typed = SWEEP.make(None, target=motorlab.step("train", env=ENV_ID, algo="ppo", timesteps=2000),
                       grid={"lr": lrs, "n_envs": n_envs})
    text = SWEEP.make(None, target=f"train {ENV_ID} --algo ppo --timesteps 2000",
                      grid=[f"lr={','.join(map(repr, lrs))}", f"n_envs={','.join(map(str, n_envs))}"])
    assert isinstance(typed.target, StepTarget) and isinstance(text.target, StepTarget)
    assert typed.grid == {"lr": lrs, "n_envs": n_envs}  # kept as given
    a, b = _trial_settings(typed.target, typed.grid), _trial_settings(text.target, text.grid)
    assert len(a) == len(b) == 2 * len(lrs) * len(n_envs)
    assert sorted(map(_key, a.values())) == sorted(map(_key, b.values()))


def _key(settings: dict) -> tuple:
    return settings["seed"], float(settings["lr"]), settings["n_envs"]


def test_a_recipe_target_sets_its_fields_under_the_grid_in_every_trial(tmp_path):
    target = motorlab.recipe("pendulum", **{"ppo.timesteps": 3000})
    assert isinstance(target, RecipeTarget) and target.text == "pendulum --set ppo.timesteps=3000"
    trials, _ = plan(target, [0], {"ppo.until_solved": [True, False]}, tmp_path)
    variants = [tomllib.loads(next(iter(t["files"].values()))) for t in trials]  # each trial's recipe
    ppo = [next(s for s in v["steps"] if s["name"] == "ppo") for v in variants]
    assert [(s["timesteps"], s["until_solved"]) for s in ppo] == [(3000, True), (3000, False)]
    assert read_target("pendulum", "sweep") == RecipeTarget(target.path, "pendulum")


@pytest.mark.parametrize("make, message", [
    (lambda: motorlab.step("train", env=ENV_ID, seed=2), "sets seed of every trial itself"),
    (lambda: motorlab.step("trian", env=ENV_ID), "did you mean train"),
    (lambda: motorlab.step("train", env=ENV_ID, timesteps=-1), "--timesteps"),
    (lambda: motorlab.step("train", env=ENV_ID, lr="fast"), "--lr"),
    (lambda: SWEEP.make(None, target=f"train {ENV_ID}", grid={"lr": []}), "non-empty list"),
    (lambda: SWEEP.make(None, target=f"train {ENV_ID}", grid={"lr": [1e-3, 1e-3]}), "repeated"),
    (lambda: SWEEP.make(None, target=f"train {ENV_ID}", grid={"lr": "1e-3"}), "--grid"),
    (lambda: SWEEP.make(None, target="  "), "give the sweep a target"),
    (lambda: TUNE.make(None, target=f"train {ENV_ID}"), "--space is required"),
    (lambda: TUNE.make(None, target=f"train {ENV_ID}", space=[]), "at least one --space"),
    (lambda: TUNE.make(None, target=f"train {ENV_ID}", space={"lr": 3}), "not int"),
    (lambda: TUNE.make(None, target=f"train {ENV_ID}",
                       space={"lr": optuna.distributions.FloatDistribution(0.1, 0.5, step=0.1)}), "stepped"),
])
def test_a_bad_target_grid_or_space_from_python_is_refused_in_one_line(make, message):
    with pytest.raises(MotorlabError, match=message) as e:
        make()
    assert "\n" not in str(e.value)


@settings_(max_examples=40, deadline=None)
@given(low=st.floats(1e-6, 1.0), ratio=st.floats(1.5, 1e4), ints=st.tuples(st.integers(0, 100), st.integers(1, 100)))
def test_optunas_distributions_and_the_space_text_are_the_same_space(low, ratio, ints):
    high = low * ratio
    if not math.isfinite(high):
        return
    dists = optuna.distributions
    typed = parse_space({"lr": dists.FloatDistribution(low, high, log=True),
                         "n": dists.IntDistribution(ints[0], ints[0] + ints[1]),
                         "hidden": dists.CategoricalDistribution([64, 128])})
    text = parse_space([f"lr=loguniform:{low!r},{high!r}", f"n=int:{ints[0]},{ints[0] + ints[1]}", "hidden=choice:64,128"])
    for key in ("lr", "n"):
        assert typed[key].distribution() == text[key].distribution()
    assert typed["hidden"].choices == (64, 128) and text["hidden"].choices == ("64", "128")  # as given


def test_a_sweep_from_python_runs_with_a_typed_target(tmp_path):
    """End to end: a `step` target and a grid of numbers, run by the sweep's door; the record names the
    target as its command line, and each trial's config holds the number given."""
    target = motorlab.step("evaluate", policy="pid", env=ENV_ID, episodes=1)
    swept = motorlab.sweep(target, seeds=1, grid={"delay": [0.0, 0.1]}, out=tmp_path / "sweep")
    assert swept.summary["sweep"] == f"evaluate pid --env {ENV_ID} --episodes 1"
    delays = sorted(float(motorlab.load(p).config["env"]["delay"]) for p in swept.path.glob("*/seed0"))
    assert delays == [0.0, 0.1]


def test_a_recipes_fields_from_python_may_be_paths_and_results(tmp_path):
    """`run_recipe` and `recipe` take a recipe's inputs as Python gives them: a Path (or a Result) is its
    path, never a TypeError from the TOML writer."""
    sar = tmp_path / "sar.npz"
    target = motorlab.recipe("sar-legs-published", sar=sar)
    assert target.fields == {"sar": str(sar)}
    with pytest.raises(MotorlabError, match="sar.npz does not exist"):  # read as the path it is, and checked
        plan(target, [0], {}, tmp_path / "sweep")
    with pytest.raises(MotorlabError, match="sar.npz does not exist"):
        motorlab.run_recipe("sar-legs-published", tmp_path / "study", sar=sar)


RECIPE_FIELDS = st.dictionaries(
    st.sampled_from(["ppo.timesteps", "ppo.seed_note", "timesteps", "note"]),
    st.one_of(st.integers(-10**6, 10**6), finite, st.booleans(), word, st.sampled_from(["3", "true", "1e-3", "a b", "x=y"])),
    max_size=3)


@settings_(max_examples=60, deadline=None)
@given(fields=RECIPE_FIELDS, command=st.sampled_from(["sweep", "tune"]))
def test_a_targets_config_reads_back_as_the_same_target(fields, command, tmp_path_factory):
    """config.toml records a sweep's or search's target as its text, and that text read back is the same
    target: a recipe with the fields it sets (text that JSON would read as a number stays text), or a
    command line of a step kind."""
    from motorlab.runs import write_toml

    cmd = {"sweep": SWEEP, "tune": TUNE}[command]
    extra = ({"grid": ["episodes=2,3"]} if command == "sweep"
             else {"space": {"episodes": optuna.distributions.IntDistribution(2, 9),
                             "noise": optuna.distributions.FloatDistribution(1.2345678901e-5, 0.3, log=True)}})
    path = tmp_path_factory.mktemp("cfg") / "config.toml"
    for target in (motorlab.recipe("pendulum", **fields), motorlab.step("evaluate", policy="random", env=ENV_ID)):
        made = cmd.make(target=target, **extra)
        write_toml(path, made.config())
        again = cmd.validate(tomllib.loads(path.read_text()))
        assert again.model_dump() == made.model_dump()
        if isinstance(target, RecipeTarget):
            assert again.target.fields == fields and again.target.path == target.path
        else:
            assert again.target.given.fields == target.given.fields


def test_a_recipe_target_takes_only_sets_after_its_name():
    with pytest.raises(MotorlabError, match="only --set FIELD=VALUE.*'--seeds'"):
        read_target("pendulum --seeds 3")
    assert read_target("pendulum --set=ppo.timesteps=5 --set note=a").fields == {"ppo.timesteps": 5, "note": "a"}


@settings_(max_examples=80, deadline=None)
@given(bounds=st.lists(st.floats(1e-12, 1e12, allow_nan=False), min_size=2, max_size=2, unique=True),
       kind=st.sampled_from(["loguniform", "uniform", "int"]))
def test_a_distributions_item_reads_back_exactly(bounds, kind):
    """What config.toml records of a space (`Dist.item`) reads back to the same bounds, to the last bit."""
    from motorlab.tuning.space import Dist, parse_dist

    low, high = sorted(bounds)
    if kind == "int":
        low, high = float(int(low)), float(int(high) + 1)
    made = Dist("k", kind, low, high)
    assert parse_dist(made.item()) == made


@settings_(max_examples=60, deadline=None)
@given(choices=st.lists(st.text(st.characters(codec="ascii", exclude_characters="|"), min_size=1, max_size=6)
                        .filter(lambda c: c.strip() == c), min_size=2, max_size=4, unique=True))
def test_a_choices_item_reads_back_as_the_same_choices(choices):
    """Choices with commas in them are written with |, which `parse_dist` splits on instead."""
    from motorlab.tuning.space import Dist, parse_dist

    made = Dist("k", "choice", choices=tuple(choices))
    assert parse_dist(made.item()) == made
