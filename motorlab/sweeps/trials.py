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


def _option_args(cmd, key: str, value: str) -> list[str]:
    """`--grid key=value` as command-line words: --key value, or the switch for booleans."""
    flag = "--" + key.lstrip("-").replace("_", "-")
    for p in cmd.params:
        if flag in getattr(p, "opts", []) or flag in getattr(p, "secondary_opts", []):
            if getattr(p, "is_flag", False):
                on = value.lower() in ("1", "true", "yes", "on")
                if not on and value.lower() not in ("0", "false", "no", "off"):
                    raise MotorlabError(f"--grid {key}: {flag} is a switch; give true or false, not {value!r}.")
                if p.secondary_opts:
                    return [p.opts[0] if on else p.secondary_opts[0]]
                return [flag] if on else []
            return [flag, value]
    options = [o for p in cmd.params for o in getattr(p, "opts", []) if o.startswith("--")]
    raise MotorlabError(f"--grid {key}: `motorlab {cmd.name}` has no option {flag}"
                        f"{did_you_mean(flag, options)}; see motorlab {cmd.name} --help.")


def _check_parses(cmd, argv: list[str], where: str) -> None:
    """Parse (not run) the command line, so a typo fails before any trial starts."""
    try:
        cmd.make_context(f"motorlab {cmd.name}", list(argv), resilient_parsing=False)
    except Exception as e:  # typer's vendored click raises its own UsageError classes
        message = e.format_message() if hasattr(e, "format_message") else str(e)
        raise MotorlabError(f"{where}: {message}") from None


def command_trials(cli: TyperGroup, command: str, settings: list[dict[str, str]], seeds: list[int],
                   sweep_dir: Path, threads: dict[str, str]) -> list[dict[str, Any]]:
    """Trials of a motorlab command line (checked against `cli`, the motorlab command): each adds
    its setting's options, --seed and --out."""
    try:
        words = shlex.split(command)
    except ValueError as e:
        raise MotorlabError(f"cannot read the command {command!r}: {e}.") from None
    if words[:1] == ["motorlab"]:
        words = words[1:]
    cmd, n = _command(cli, words)
    step_kind = for_command(" ".join(words[:n]))
    args = words[n:]
    for fixed in ("--seed", "--out"):
        if any(a == fixed or a.startswith(fixed + "=") for a in args):
            raise MotorlabError(f"the sweep sets {fixed} of every trial itself; drop {fixed} from the command.")
    head = words[:n]
    out = []
    for setting in settings:
        extra = [w for k, v in setting.items() for w in _option_args(cmd, k, v)]
        name = label(setting)
        argv_seed0 = [*args, *extra, "--seed", "0", "--out", "x"]
        _check_parses(cmd, argv_seed0, f"setting {name}")
        if "progress" in {p.name for p in cmd.params}:
            extra.append("--no-progress")  # bars belong to the sweep, not to each trial's log
        for s in seeds:
            run_dir = sweep_dir / name / f"seed{s}"
            out.append(trial(f"{name}/seed{s}", name, s, [*head, *args, *extra, "--seed", str(s), "--out", run_dir],
                             run_dir, sweep_dir / "logs" / f"{name}-seed{s}.log", threads,
                             resume_argv=step_kind.resume_argv(run_dir) if step_kind else None))
    return out


def recipe_variant(data: dict[str, Any], setting: dict[str, str], seed: int, source: str) -> dict[str, Any]:
    """The recipe's TOML data with the setting's fields set (`set_fields`: FIELD, STEP.FIELD or one
    of its [inputs]) and every step's seed set to `seed`.

    Raises:
        MotorlabError: a step name or field the recipe does not have.
    """
    data = set_fields(data, setting, source, flag="--grid")
    data.pop(SEEDS, None)  # one seed per trial: the sweep's
    data["defaults"] = {k: v for k, v in data.get("defaults", {}).items() if k != SEEDS}
    for s in data["steps"]:
        s.pop(SEEDS, None)
        if "seed" in step_fields(s):
            s["seed"] = seed
    return data


def recipe_trials(path: Path, settings: list[dict[str, str]], seeds: list[int], sweep_dir: Path,
                  threads: dict[str, str]) -> list[dict[str, Any]]:
    """Trials of a whole study: each runs `motorlab run` on a variant of the recipe written
    to <sweep>/recipes/, with the setting applied and all seeds set to the trial's."""
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise MotorlabError(f"cannot read recipe {path}: {e}") from None
    planned = []  # every variant is built (and the first of each setting validated) before any file is written
    for setting in settings:
        name = label(setting)
        for k, s in enumerate(seeds):
            text = tomli_w.dumps(recipe_variant(data, setting, s, str(path)))
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
