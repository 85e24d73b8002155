"""Trials: one seed of one setting, as one motorlab command line that writes one run folder.

A trial is plain data (a dict of strings and lists) so that any backend can run it: a
local process pool, or a Ray Tune worker on another machine that shares the file system.
Its command line is `python -m motorlab ARGV`, so a trial behaves exactly like the same
command typed by hand, and its run folder is the same either way.

A finished trial leaves `sweep_trial.toml` (its command line) beside its summary.json; a
sweep run again into the same folder skips those trials and runs the rest.
"""

from __future__ import annotations

import hashlib
import json
import shlex
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import tomli_w

from motorlab.errors import MotorlabError, did_you_mean
from motorlab.kinds import KINDS, for_command
from motorlab.recipes import SEEDS, bundled, find_recipe, parse_recipe, set_fields, step_fields
from motorlab.runs import atomic_write_text, finished_with, is_complete, toml_holds, write_toml
from motorlab.sweeps.grid import label

if TYPE_CHECKING:
    from typer.core import TyperGroup  # the motorlab command, handed down by the CLI

    from motorlab.stepkind import StepKind

TRIAL_FILE = "sweep_trial.toml"
STARTED_FILE = "sweep_trial_started.toml"  # the command line a trial's folder was started with
# Commands of step kinds that take a seed (and --out): the ones a sweep can repeat.
SWEEPABLE = tuple(k.command for k in KINDS.values() if k.command and "seed" in k.settings.model_fields)


def recipe_path(target: str) -> Path | None:
    """The recipe file TARGET names, or None when TARGET is a command line (sweep and tune targets)."""
    if len(target.split()) == 1 and (target.endswith(".toml") or target in bundled()):
        return find_recipe(target)
    return None


def trial(name: str, setting: str, seed: int, argv: list[str], run_dir: Path, log: Path,
          env: dict[str, str] | None = None, fingerprint: str = "",
          resume_argv: list[str] | None = None) -> dict[str, Any]:
    """`fingerprint`: a hash of inputs the command line only names (a recipe file's text);
    `resume_argv`: the command line that continues the run where an interrupted start left it."""
    return {"name": name, "setting": setting, "seed": seed, "argv": [str(a) for a in argv],
            "run_dir": str(Path(run_dir).resolve()), "log": str(Path(log).resolve()), "env": env or {},
            "fingerprint": fingerprint, "resume_argv": [str(a) for a in resume_argv] if resume_argv else None}


def _marker(t: dict[str, Any]) -> dict[str, Any]:
    return {"argv": t["argv"], "fingerprint": t["fingerprint"]}


def is_finished(t: dict[str, Any]) -> bool:
    """The trial's run folder finished with this very command line (and recipe text)."""
    return finished_with(Path(t["run_dir"]), _marker(t), TRIAL_FILE)


def mark_finished(t: dict[str, Any]) -> None:
    write_toml(Path(t["run_dir"]) / TRIAL_FILE, _marker(t))


def mark_started(t: dict[str, Any]) -> None:
    write_toml(Path(t["run_dir"]) / STARTED_FILE, _marker(t))


def launch_argv(t: dict[str, Any]) -> list[str]:
    """The command line that runs `t`: its own, or its resume command line (e.g. `train --resume
    RUN_DIR`) when an interrupted start of this very command line left a checkpoint (then only the
    rest of the budget is trained; the result is the same run folder)."""
    run_dir = Path(t["run_dir"])
    if (t.get("resume_argv") and not is_complete(run_dir)
            and toml_holds(run_dir / STARTED_FILE, _marker(t))):  # else: another command line started it
        return t["resume_argv"]
    return t["argv"]


def _command(group: TyperGroup, words: list[str]):
    """The click command for `words` ("train ...", "dynamics fit ..."), and how many words name it."""
    names = [" ".join(words[:2]), words[0]] if len(words) > 1 else [words[0]] if words else []
    for name in names:
        if name in SWEEPABLE:
            cmd = group
            for part in name.split():
                cmd = cmd.commands[part]
            return cmd, len(name.split())
    given = " ".join(words[:2]) if words else ""
    raise MotorlabError(f"cannot sweep {given!r}: give a recipe (name or .toml file) or one of the commands "
                        f"{', '.join(SWEEPABLE)}, quoted, e.g. motorlab sweep \"train InvertedPendulum-v5 "
                        f"--preset fast\" --seeds 5{did_you_mean(given, SWEEPABLE)}")


def _option_args(cmd, key: str, value: str, flag_given: str = "--grid") -> list[str]:
    """`--grid key=value` as command-line words: --key value, or the switch for booleans
    (`flag_given`: the option the key came from, named in errors)."""
    flag = "--" + key.lstrip("-").replace("_", "-")
    for p in cmd.params:
        if flag in getattr(p, "opts", []) or flag in getattr(p, "secondary_opts", []):
            if getattr(p, "is_flag", False):
                on = value.lower() in ("1", "true", "yes", "on")
                if not on and value.lower() not in ("0", "false", "no", "off"):
                    raise MotorlabError(f"{flag_given} {key}: {flag} is a switch; give true or false, not {value!r}.")
                if p.secondary_opts:
                    return [p.opts[0] if on else p.secondary_opts[0]]
                return [flag] if on else []
            return [flag, value]
    options = [o for p in cmd.params for o in getattr(p, "opts", []) if o.startswith("--")]
    raise MotorlabError(f"{flag_given} {key}: `motorlab {cmd.name}` has no option {flag}"
                        f"{did_you_mean(flag, options)}; see motorlab {cmd.name} --help.")


def parse_options(cmd, argv: list[str], where: str) -> dict[str, Any]:
    """Parse (not run) the command line, so a typo fails before any trial starts. Returns its
    options' values by parameter name.

    Raises:
        MotorlabError: what the command line's parser says, after `where`.
    """
    try:
        return cmd.make_context(f"motorlab {cmd.name}", list(argv), resilient_parsing=False).params
    except Exception as e:  # typer's vendored click raises its own UsageError classes
        message = e.format_message() if hasattr(e, "format_message") else str(e)
        raise MotorlabError(f"{where}: {message}") from None


# ---- SB3 hyperparameters: what a command line's --set passes to the algorithm -----------------

HYPERPARAMETERS = "--set"  # KEY=VALUE (VALUE as JSON): keyword arguments of the SB3 algorithm
# the settings that decide which algorithm a command line trains, as train reads them: --config's
# file under --preset and --preset-file (see motorlab.rl.config.resolve), under --algo
ALGORITHM_FIELDS = ("algo", "preset", "preset_file")
CONFIG = "config"


def hyperparameters(cmd, params: dict[str, Any], where: str) -> dict[str, Any]:
    """The SB3 hyperparameters a parsed command line gives with --set, read as the command reads
    them ({} for a command without --set)."""
    option = next((p for p in cmd.params if HYPERPARAMETERS in getattr(p, "opts", ())), None)
    given: dict[str, Any] = {}
    for item in (params.get(option.name) or ()) if option is not None else ():
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise MotorlabError(f"{where}: --set {item!r}: write KEY=VALUE, e.g. --set n_steps=1024.")
        given[key] = hyperparameter_value(text)
    return given


def hyperparameter_value(text: str) -> Any:
    """A --set VALUE as the command reads it: JSON, else the text itself."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def algorithm(step_kind: StepKind, params: dict[str, Any], where: str) -> str | None:
    """The algorithm a parsed command line trains with, after its preset, preset file and --config
    (None for a command that trains nothing).

    Raises:
        MotorlabError: --config cannot be read, or the settings that choose the algorithm are wrong
            (an unknown preset).
    """
    if ALGORITHM_FIELDS[0] not in step_kind.settings.model_fields:
        return None
    fields: dict[str, Any] = {}
    if params.get(CONFIG):
        try:
            fields = tomllib.loads(Path(params[CONFIG]).read_text())
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
            raise MotorlabError(f"{where}: --config {params[CONFIG]}: cannot read it ({e}).") from None
    fields.update({k: params[k] for k in ALGORITHM_FIELDS if params.get(k) is not None})
    if fields.get("preset_file"):
        fields["preset_file"] = str(Path(fields["preset_file"]).resolve())
    try:
        return getattr(step_kind.make(**fields), ALGORITHM_FIELDS[0], None)
    except MotorlabError as e:
        raise MotorlabError(f"{where}: {e}") from None


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


def _check_command(cmd, step_kind: StepKind | None, argv: list[str], where: str) -> None:
    """A trial's command line parses, and the SB3 hyperparameters it gives exist for its algorithm
    with values of the right type (misspelt, they would fail every trial, one after the other)."""
    params = parse_options(cmd, argv, where)
    given = hyperparameters(cmd, params, where)
    if not given or step_kind is None:
        return
    algo = algorithm(step_kind, params, where)
    if algo is None or not takes_hyperparameters(algo):
        return  # the LQR learner ignores them, as training does
    try:
        check_hyperparameters(algo, given)
    except MotorlabError as e:
        raise MotorlabError(f"{where}: {e}") from None


def command_of(cli: TyperGroup, command: str) -> tuple[Any, StepKind | None, list[str], list[str]]:
    """The click command a sweep or tune target runs, its step kind, the words naming the command
    and the rest (its arguments).

    Raises:
        MotorlabError: the command line cannot be split into words, or names no sweepable command.
    """
    try:
        words = shlex.split(command)
    except ValueError as e:
        raise MotorlabError(f"cannot read the command {command!r}: {e}.") from None
    if words[:1] == ["motorlab"]:
        words = words[1:]
    cmd, n = _command(cli, words)
    return cmd, for_command(" ".join(words[:n])), words[:n], words[n:]


def command_trials(cli: TyperGroup, command: str, settings: list[dict[str, str]], seeds: list[int],
                   sweep_dir: Path, threads: dict[str, str], flag: str = "--grid") -> list[dict[str, Any]]:
    """Trials of a motorlab command line (checked against `cli`, the motorlab command): each adds
    its setting's options, --seed and --out. `flag`: the option the settings came from (--grid,
    tune's --space), named in errors.

    Raises:
        MotorlabError: a setting's command line does not parse, or gives an SB3 hyperparameter its
            algorithm does not have (before any trial is planned, let alone run).
    """
    cmd, step_kind, head, args = command_of(cli, command)
    for fixed in ("--seed", "--out"):
        if any(a == fixed or a.startswith(fixed + "=") for a in args):
            raise MotorlabError(f"the sweep sets {fixed} of every trial itself; drop {fixed} from the command.")
    out = []
    for setting in settings:
        extra = [w for k, v in setting.items() for w in _option_args(cmd, k, v, flag)]
        name = label(setting)
        argv_seed0 = [*args, *extra, "--seed", "0", "--out", "x"]
        where = f"setting {name}" if flag == "--grid" else f"{flag} {name}"  # a sweep's, named as its folder
        _check_command(cmd, step_kind, argv_seed0, where)
        if "progress" in {p.name for p in cmd.params}:
            extra.append("--no-progress")  # bars belong to the sweep, not to each trial's log
        for s in seeds:
            run_dir = sweep_dir / name / f"seed{s}"
            out.append(trial(f"{name}/seed{s}", name, s, [*head, *args, *extra, "--seed", str(s), "--out", run_dir],
                             run_dir, sweep_dir / "logs" / f"{name}-seed{s}.log", threads,
                             resume_argv=step_kind.resume_argv(run_dir) if step_kind else None))
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
        if "seed" in step_fields(s):
            s["seed"] = seed
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
    for setting in settings:
        name = label(setting)
        for k, s in enumerate(seeds):
            text = tomli_w.dumps(recipe_variant(data, setting, s, str(path), flag))
            if k == 0:
                parse_recipe(text, f"{path} with {name}")
            planned.append((name, s, text))
    out = []
    for name, s, text in planned:
        recipe_file = sweep_dir / "recipes" / f"{name}-seed{s}.toml"
        atomic_write_text(recipe_file, text)
        run_dir = sweep_dir / name / f"seed{s}"
        out.append(trial(f"{name}/seed{s}", name, s, ["run", recipe_file.resolve(), "--out", run_dir], run_dir,
                         sweep_dir / "logs" / f"{name}-seed{s}.log", threads,
                         hashlib.sha256(text.encode()).hexdigest()[:16]))
    return out
