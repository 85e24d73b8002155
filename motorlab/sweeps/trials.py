"""Trials: one seed of one setting, as one job (motorlab.jobs) that writes one run folder.

A sweep's or search's target is read once: a command line ("train InvertedPendulum-v5
--preset fast") becomes its step kind and the fields it gives (`Target`), checked by the kind's
settings model; each setting of the grid sets more fields, and each trial is the job of those
settings with its seed and run folder. A trial is plain data (a dict), so that any backend can
run it: a local process pool, or a Ray worker on another machine that shares the file system.
Its process is `python -m motorlab.worker JOB` (motorlab/worker.py), so a trial runs exactly
what the same command typed by hand runs, into the same run folder.

A finished trial leaves `sweep_trial.toml` (its job's identity) beside its summary.json; a sweep
run again into the same folder skips those trials and runs the rest.
"""

from __future__ import annotations

import hashlib
import shlex
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomli_w

from motorlab import jobs
from motorlab.commandline import Given, json_or_text, numbers, pairs, parse, value_kind
from motorlab.errors import MotorlabError, did_you_mean, mask_secrets
from motorlab.kinds import KINDS, for_command
from motorlab.launcher import trial
from motorlab.recipes import SEEDS, bundled, find_recipe, parse_recipe, set_fields, step_fields
from motorlab.settings import Settings
from motorlab.stepkind import StepKind
from motorlab.sweeps.grid import labels

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


# ---- a command line target, read once -------------------------------------------------------------


@dataclass(frozen=True)
class Target:
    """A sweep's or search's command line in its step kind's terms: the fields it gives."""

    text: str  # as recorded: credentials masked
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

    def fields(self, values: dict[str, str], flag: str = "--grid", hyperparams: set[str] = frozenset()) -> dict:
        """The target's fields with `values` (text, as a command line gives it) set: an option's value read as
        its command line reads it; a key that is no option (or named in `hyperparams`) an SB3 hyperparameter.

        Raises:
            MotorlabError: a key the command has no option for, and takes no hyperparameters.
        """
        fields = dict(self.given.fields)
        model = self.kind.settings
        for key, text in values.items():
            name = key.removeprefix("set.")
            if key in hyperparams or name in hyperparams or key.startswith("set.") or name not in self.options():
                if not self.takes_hyperparameters() or not (key in hyperparams or name in hyperparams
                                                            or key.startswith("set.")):
                    options = sorted(f"--{o.replace('_', '-')}" for o in self.options())
                    flag_name = "--" + name.replace("_", "-")
                    raise MotorlabError(f"{flag} {key}: `motorlab {self.name}` has no option {flag_name}"
                                        f"{did_you_mean(flag_name, options)}; see motorlab {self.name} --help.")
                fields[HYPERPARAMETERS] = {**fields.get(HYPERPARAMETERS, {}), name: json_or_text(text)}
                continue
            info = model.model_fields.get(name)
            kind = value_kind(info.annotation) if info is not None else "text"
            if kind == "flag":
                if text.lower() not in SWITCH:
                    raise MotorlabError(f"{flag} {key}: --{name.replace('_', '-')} is a switch; give true or false, "
                                        f"not {text!r}.")
                fields[name] = SWITCH[text.lower()]
            elif kind == "numbers":
                fields[name] = numbers(text, f"{flag} {key}")
            elif kind == "many":
                fields[name] = [text]
            elif kind == "pairs":
                fields[name] = {**fields.get(name, {}), **pairs([text], f"{flag} {key}")}
            else:
                fields[name] = text
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


def parse_target(command: str, owner: str = "sweep") -> Target:
    """The step kind a sweep or tune target runs, the fields its command line gives, and the
    invocation options it applies (`owner`: "sweep" or "tune", named in errors).

    Raises:
        MotorlabError: the command line cannot be split into words, names no sweepable command,
            does not parse, sets --seed (the sweep sets it), or gives an invocation option the
            sweep does not apply per trial (--out, --resume, --overwrite).
    """
    try:
        words = shlex.split(command)
    except ValueError as e:
        raise MotorlabError(f"cannot read the command {mask_secrets(command)!r}: {e}.") from None
    if words[:1] == ["motorlab"]:
        words = words[1:]
    for n in (2, 1):
        name = " ".join(words[:n])
        if len(words) >= n and name in SWEEPABLE:
            kind = for_command(name)
            break
    else:
        given = mask_secrets(" ".join(words[:2]))
        raise MotorlabError(f"cannot {owner} {given!r}: give a recipe (name or .toml file) or one of the commands "
                            f"{', '.join(SWEEPABLE)}, quoted, e.g. motorlab {owner} \"train InvertedPendulum-v5 "
                            f"--preset fast\" --seeds 5{did_you_mean(given, SWEEPABLE)}")
    given = parse(kind, words[n:], f"motorlab {name}")
    if kind.SEED in given.fields:
        raise MotorlabError(f"the {owner} sets --{kind.SEED} of every trial itself; drop --{kind.SEED} from the "
                            "command.")
    for option, value in given.how.items():
        if option not in APPLIED and value not in (None, False):
            raise MotorlabError(_refusal(option, owner))
    fields = given.fields
    if given.how.get("config"):  # --config: a run's settings under the given ones, read here once
        fields = kind.with_config(Path(given.how["config"]), given.fields)
    return Target(mask_secrets(command), kind, Given(fields, {}), tuple(given.how.get("track") or ()))


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


def command_trials(target: Target, settings: list[dict[str, str]], seeds: list[int], sweep_dir: Path,
                   threads: dict[str, str], flag: str = "--grid", hyperparams: set[str] = frozenset()
                   ) -> list[dict[str, Any]]:
    """Trials of a command-line target: each its setting's fields, its seed and its run folder.
    `flag`: the option the settings came from (--grid, tune's --space), named in errors.

    Raises:
        MotorlabError: a setting the command's settings refuse, or an SB3 hyperparameter its
            algorithm does not have (before any trial is planned, let alone run).
    """
    out = []
    for setting, name in zip(settings, labels(settings)):
        where = f"setting {name}" if flag == "--grid" else f"{flag} {name}"  # a sweep's, named as its folder
        fields = target.fields(setting, flag, hyperparams)
        target.settings(target.kind.with_seed(fields, 0), where)
        for s in seeds:
            run_dir = sweep_dir / name / f"seed{s}"
            checked = target.settings(target.kind.with_seed(fields, s), where)
            job = jobs.job(target.kind.name, checked.config(), {"out": run_dir.resolve()})
            out.append(trial(f"{name}/seed{s}", name, s, job, run_dir, sweep_dir / "logs" / f"{name}-seed{s}.log",
                             threads))
    return out


def recipe_variant(data: dict[str, Any], setting: dict[str, str], seed: int, source: str,
                   flag: str = "--grid") -> dict[str, Any]:
    """The recipe's TOML data with the setting's fields set (`set_fields`: FIELD, STEP.FIELD or one
    of its [inputs]) and every step's seed set to `seed`.

    Raises:
        MotorlabError: a step name or field the recipe does not have.
    """
    data = set_fields(data, setting, source, flag=flag)
    data.pop(SEEDS, None)  # one seed per trial: the sweep's
    data["defaults"] = {k: v for k, v in data.get("defaults", {}).items() if k != SEEDS}
    for s in data["steps"]:
        s.pop(SEEDS, None)
        if StepKind.SEED in step_fields(s):  # every kind names its seed field alike (StepKind.SEED)
            s[StepKind.SEED] = seed
    return data


def recipe_trials(path: Path, settings: list[dict[str, str]], seeds: list[int], sweep_dir: Path,
                  threads: dict[str, str], flag: str = "--grid") -> list[dict[str, Any]]:
    """Trials of a whole study: each runs `motorlab run` on a variant of the recipe written
    to <sweep>/recipes/, with the setting applied and all seeds set to the trial's (`flag`: the
    option the settings came from, named in errors)."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise MotorlabError(f"cannot read recipe {path}: {e}") from None
    planned = []  # every variant is built (and the first of each setting validated) before any file is written
    for setting, name in zip(settings, labels(settings)):
        for k, s in enumerate(seeds):
            text = tomli_w.dumps(recipe_variant(data, setting, s, str(path), flag))
            if k == 0:
                parse_recipe(text, f"{path} with {name}")
            planned.append((name, s, text))
    out = []
    for name, s, text in planned:
        recipe_file = sweep_dir / "recipes" / f"{name}-seed{s}.toml"  # written when the trial starts
        run_dir = sweep_dir / name / f"seed{s}"
        job = jobs.job("run", {"recipe": str(recipe_file.resolve())}, {"out": run_dir.resolve()})
        out.append(trial(f"{name}/seed{s}", name, s, job, run_dir, sweep_dir / "logs" / f"{name}-seed{s}.log",
                         threads, hashlib.sha256(text.encode()).hexdigest()[:16], files={recipe_file: text}))
    return out
