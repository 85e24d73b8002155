"""What a sweep or a search runs: a step kind with the fields its trials share (`StepTarget`), or a
recipe with fields set (`RecipeTarget`).

A target is read once, where it enters: the command line's text by `read_target` (a recipe's name or
file, else a command line such as "train InvertedPendulum-v5 --preset fast", parsed by the kind's own
command, `motorlab.commandline`), Python's keyword arguments by `step_target` and `recipe_target`
(`motorlab.sweep(motorlab.step_target("train", env=..., preset="fast"), grid={"lr": [3e-4, 1e-3]})`).
From there on the sweep, the search and their trials see only typed fields: a grid's values set as
they are given, text read as the command line reads it and numbers from Python kept numbers.
"""

from __future__ import annotations

import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from pydantic import ConfigDict, Field, field_serializer, field_validator

from motorlab.commandline import Given, command_line, json_or_text, numbers, pairs, parse, value_kind
from motorlab.errors import MotorlabError, did_you_mean, mask_secrets
from motorlab.kinds import KINDS, for_command
from motorlab.launcher import ExecutionSettings
from motorlab.recipes import bundled, find_recipe, set_fields
from motorlab.settings import Settings
from motorlab.stepkind import StepKind

# Commands of step kinds that take a seed (and --out): the ones a sweep can repeat.
SWEEPABLE = tuple(k.command for k in KINDS.values() if k.command and k.takes_seed())
HYPERPARAMETERS = "hyperparams"  # the field of SB3 keyword arguments (train's --set KEY=VALUE)
ALGORITHM_FIELDS = ("algo", "preset", "preset_file")  # the fields that decide which algorithm trains
SWITCH = {"1": True, "true": True, "yes": True, "on": True, "0": False, "false": False, "no": False, "off": False}


def recipe_path(target: str) -> Path | None:
    """The recipe file TARGET names, or None when TARGET is a command line (sweep and tune targets)."""
    if len(target.split()) == 1 and (target.endswith(".toml") or target in bundled()):
        return find_recipe(target)
    return None


@dataclass(frozen=True)
class StepTarget:
    """A step kind and the fields a sweep's or search's trials share (from a command line, or from Python)."""

    text: str  # as recorded and shown: the command line, credentials masked
    kind: StepKind
    given: Given
    track: tuple[str, ...] = ()  # its own --track: its trials are tracked there too (motorlab.trackers.also)

    @property
    def name(self) -> str:
        return self.kind.command

    def options(self) -> set[str]:
        """The names a --grid or --space key may give: the settings' fields and flat env settings."""
        return self.kind.settings.fields() - {self.kind.SEED}

    def takes_hyperparameters(self) -> bool:
        return HYPERPARAMETERS in self.kind.settings.model_fields

    def fields(self, values: dict[str, Any], flag: str = "--grid", hyperparams: set[str] = frozenset()) -> dict:
        """The target's fields with `values` set: text (as a command line gives it) read as its command line
        reads it, any other value (from Python) as it is; a key that is no option (or named in `hyperparams`)
        an SB3 hyperparameter.

        Raises:
            MotorlabError: a key the command has no option for, and takes no hyperparameters.
        """
        fields = dict(self.given.fields)
        model = self.kind.settings
        for key, value in values.items():
            name = key.removeprefix("set.")
            if key in hyperparams or name in hyperparams or key.startswith("set.") or name not in self.options():
                if not self.takes_hyperparameters() or not (key in hyperparams or name in hyperparams
                                                            or key.startswith("set.")):
                    options = sorted(f"--{o.replace('_', '-')}" for o in self.options())
                    flag_name = "--" + name.replace("_", "-")
                    hyper = (f"; an SB3 hyperparameter is given as {flag} set.{name}=..."
                             if self.takes_hyperparameters() and not key.startswith("set.") else "")
                    raise MotorlabError(f"{flag} {key}: `motorlab {self.name}` has no option {flag_name}"
                                        f"{did_you_mean(flag_name, options)}{hyper}; see motorlab {self.name} --help.")
                value = json_or_text(value) if isinstance(value, str) else value
                fields[HYPERPARAMETERS] = {**fields.get(HYPERPARAMETERS, {}), name: value}
                continue
            if not isinstance(value, str):  # a value from Python: the settings model judges it as it is
                fields[name] = value
                continue
            info = model.model_fields.get(name)
            kind = value_kind(info.annotation) if info is not None else "text"
            if kind == "flag":
                if value.lower() not in SWITCH:
                    raise MotorlabError(f"{flag} {key}: --{name.replace('_', '-')} is a switch; give true or false, "
                                        f"not {value!r}.")
                fields[name] = SWITCH[value.lower()]
            elif kind == "numbers":
                fields[name] = numbers(value, f"{flag} {key}")
            elif kind == "many":
                fields[name] = [value]
            elif kind == "pairs":
                fields[name] = {**fields.get(name, {}), **pairs([value], f"{flag} {key}")}
            else:
                fields[name] = value
        return fields

    def settings(self, fields: dict[str, Any], where: str) -> Settings:
        """The kind's settings of these fields, with the SB3 hyperparameters checked against the algorithm.

        Raises:
            MotorlabError: a value the settings refuse, an unknown or wrongly typed hyperparameter.
        """
        try:
            settings = self.kind.make(**fields)
            given = fields.get(HYPERPARAMETERS) or {}
            algo = getattr(settings, "algo", None)
            if given and algo is not None and takes_hyperparameters(algo):
                check_hyperparameters(algo, given)
        except MotorlabError as e:
            raise MotorlabError(f"{where}: {e}") from None
        return settings


# A target's invocation options (--out, --track, train's --config, ...): each is applied or refused here,
# never dropped. Applied: --config (that run's settings under the given ones) and --track (the sweep's or
# search's trials are tracked there too: motorlab.trackers.also). Refused: what the sweep or search sets
# itself, or owns for all its trials. Any option an invocation model gains later is refused until it is
# given a meaning here.
APPLIED = ("config", "track")
OWN = {"out": "the {owner} sets --out of every trial itself; drop --out from the command (motorlab {owner} --out DIR "
              "names the {owner}'s folder)."}


def _refusal(option: str, owner: str) -> str:
    """The one line refusing `option` inside a target of `owner` (sweep or tune), naming where it goes."""
    if option in OWN:
        return OWN[option].format(owner=owner)
    flag = "--" + option.replace("_", "-")
    return (f"{flag} inside a {owner} target is not applied per trial; give it to the {owner}: "
            f"motorlab {owner} \"TARGET\" ... {flag}.")


def parse_target(command: str, owner: str = "sweep") -> StepTarget:
    """The step kind a sweep or tune target runs, the fields its command line gives, and the
    invocation options it applies (`owner`: "sweep" or "tune", named in errors).

    Raises:
        MotorlabError: the command line cannot be split into words, names no sweepable command,
            does not parse, sets --seed (the sweep sets it), or gives an invocation option the
            sweep does not apply per trial (--out, --resume, --overwrite).
    """
    return _step_target(command, target_words(command, owner), owner)


def target_words(text: str, owner: str) -> list[str]:
    """The target's text split as a shell splits it (the one place it is split).

    Raises:
        MotorlabError: unbalanced quotes or a dangling escape.
    """
    try:
        return shlex.split(text)
    except ValueError as e:
        raise MotorlabError(f"cannot read the {owner} target {mask_secrets(text)!r}: {e}.") from None


def _step_target(command: str, words: list[str], owner: str) -> StepTarget:
    if words[:1] == ["motorlab"]:
        words = words[1:]
    for n in (2, 1):
        name = " ".join(words[:n])
        if len(words) >= n and name in SWEEPABLE:
            kind = for_command(name)
            break
    else:
        given = mask_secrets(" ".join(words[:2]))
        raise MotorlabError(f"the {owner} target {given!r} is no recipe or command: give a recipe (name or .toml "
                            f"file) or one of the commands "
                            f"{', '.join(SWEEPABLE)}, quoted, e.g. motorlab {owner} \"train InvertedPendulum-v5 "
                            f"--preset fast\" --seeds 5{did_you_mean(given, SWEEPABLE)}")
    given = parse(kind, words[n:], f"motorlab {name}")
    if kind.SEED in given.fields:
        raise MotorlabError(f"the {owner} sets --{kind.SEED} of every trial itself; drop --{kind.SEED} from the "
                            "target.")
    for option, value in given.how.items():
        if option not in APPLIED and value not in (None, False):
            raise MotorlabError(_refusal(option, owner))
    fields = given.fields
    if given.how.get("config"):  # --config: a run's settings under the given ones, read here once
        fields = kind.with_config(Path(given.how["config"]), given.fields)
    return StepTarget(mask_secrets(command), kind, Given(fields, {}), tuple(given.how.get("track") or ()))

def takes_hyperparameters(algo: str | None) -> bool:
    """The algorithm is an SB3 one (the LQR learner takes no hyperparameters, and ignores them)."""
    from motorlab.rl.sb3 import ALGORITHMS  # SB3 and torch: seconds of imports, only when hyperparameters are given

    return algo in ALGORITHMS


def check_hyperparameters(algo: str, given: dict[str, Any]) -> None:
    """Names and values of SB3 hyperparameters, judged as training will judge them.

    Raises:
        MotorlabError: an unknown name (with close matches) or a wrongly typed value.
    """
    from motorlab.rl.sb3 import check_hyperparams

    check_hyperparams(algo, given)


@dataclass(frozen=True)
class RecipeTarget:
    """A recipe, with fields and inputs set for every trial (`set_fields`: FIELD, STEP.FIELD or an input)."""

    path: Path
    name: str  # as given: a bundled recipe's name or the file
    fields: dict[str, Any] = field(default_factory=dict)

    @property
    def text(self) -> str:
        """As recorded and shown: the recipe as given, and the fields set as `motorlab run --set` gives them."""
        if not self.fields:
            return mask_secrets(self.name)
        # text that JSON would read as something else ("3", "true") is written as JSON text, so that
        # `read_target` gives back the same value
        sets = [["--set", f"{k}={v if isinstance(v, str) and json_or_text(v) == v else json.dumps(v)}"]
                for k, v in self.fields.items()]
        return mask_secrets(shlex.join([self.name, *(w for pair in sets for w in pair)]))

    def data(self, data: dict[str, Any], source: str, flag: str) -> dict[str, Any]:
        """The recipe's TOML data with this target's fields set."""
        return set_fields(data, self.fields, source, flag=flag) if self.fields else data


Target = StepTarget | RecipeTarget


def read_target(text: str, owner: str = "sweep") -> Target:
    """The target the command line's TARGET names: a recipe (bundled name or .toml file), else a
    command line of a sweepable kind (`parse_target`).

    Raises:
        MotorlabError: an empty target, a recipe that is not there, a command line that does not parse.
    """
    if not text.strip():
        raise MotorlabError(f"give the {owner} a target: a recipe or a motorlab command line in quotes.")
    words = target_words(text, owner)
    path = recipe_path(words[0]) if words and words[0] not in SWEEPABLE else None
    if path is None:
        return _step_target(text, words, owner)
    return RecipeTarget(path, words[0], recipe_sets(words[1:], f"{owner} target {words[0]}"))


def recipe_sets(words: list[str], where: str) -> dict[str, Any]:
    """The fields `--set FIELD=VALUE` words after a recipe's name set (as `motorlab run --set` reads
    them: JSON where it is JSON, else text); what `RecipeTarget.text` writes reads back the same.

    Raises:
        MotorlabError: a word that is not --set FIELD=VALUE.
    """
    items = []
    rest = iter(words)
    for word in rest:
        item = word.removeprefix("--set=") if word.startswith("--set=") else next(rest, None) if word == "--set" else None
        if item is None or "=" not in item:
            raise MotorlabError(f"{where}: after a recipe's name give only --set FIELD=VALUE, not {word!r}; "
                                f"e.g. \"pendulum --set ppo.timesteps=20000\".")
        items.append(item)
    return pairs(items, "--set")  # KEY=VALUE as every --set reads it


def step_target(command: str, owner: str = "sweep", **fields: Any) -> StepTarget:
    """The target of a step kind from Python: `command` names it as the CLI does ("train", "dynamics fit"),
    `fields` are its settings as keyword arguments (None: the default), judged by its settings model.

    Raises:
        MotorlabError: a kind no sweep can repeat, a seed given (the sweep sets it), a setting refused.
    """
    kind = for_command(command) if command in SWEEPABLE else None
    if kind is None:
        raise MotorlabError(f"cannot {owner} {command!r}: give one of {', '.join(SWEEPABLE)}"
                            f"{did_you_mean(command, SWEEPABLE)}.")
    given = {k: v.as_posix() if isinstance(v, Path) else v for k, v in fields.items() if v is not None}
    if kind.SEED in given:
        raise MotorlabError(f"the {owner} sets {kind.SEED} of every trial itself; drop {kind.SEED}=.")
    target = StepTarget(mask_secrets(shlex.join([*command.split(), *command_line(kind, given)])), kind, Given(given, {}))
    target.settings(kind.with_seed(given, 0), f"{owner} target {command}")  # judged now, not per trial
    return target


def recipe_target(recipe: str | Path, **fields: Any) -> RecipeTarget:
    """The target of a recipe (bundled name or .toml file) from Python, with `fields` set in every trial.

    Raises:
        MotorlabError: a recipe that is not there.
    """
    return RecipeTarget(find_recipe(str(recipe)), str(recipe), dict(fields))


class TargetSettings(ExecutionSettings):
    """The settings of a command that repeats a target (sweep, tune): the target read once, here, from the
    command line's text (`read_target`) or as Python gives it (`step_target`, `recipe_target`)."""

    model_config = ConfigDict(arbitrary_types_allowed=True)
    owner: ClassVar[str]  # the command's name, in errors

    target: str | StepTarget | RecipeTarget = Field(description=(
        "A recipe (bundled name or .toml file: each trial runs the whole study) or a motorlab command line in quotes "
        "(train, evaluate, mpc, dynamics fit, ...); each trial gets its own seed and folder. Its --config and "
        "--track apply to every trial; --out, --overwrite and --resume are this command's own"))

    @field_validator("target")
    @classmethod
    def _read_target(cls, value: str | Target) -> Target:
        return read_target(value, cls.owner) if isinstance(value, str) else value

    @field_serializer("target")
    def _target_text(self, target: Target) -> str:
        """config.toml records the target as its text, which `read_target` reads back to the same target."""
        return target.text
