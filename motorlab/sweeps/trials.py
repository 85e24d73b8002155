"""Trials: one seed of one setting, as one job (motorlab.jobs) that writes one run folder.

A sweep's or search's target is read once, where it enters (motorlab.sweeps.targets): a step kind
and the fields it gives (`StepTarget`), checked by the kind's settings model, or a recipe with
fields set (`RecipeTarget`); each setting of the grid sets more fields, and each trial is the job
of those settings with its seed and run folder. A trial is plain data (a dict), so that any backend can
run it: a local process pool, or a Ray worker on another machine that shares the file system.
Its process is `python -m motorlab.worker JOB` (motorlab/worker.py), so a trial runs exactly
what the same command typed by hand runs, into the same run folder.

A finished trial leaves `sweep_trial.toml` (its job's identity) beside its summary.json; a sweep
run again into the same folder skips those trials and runs the rest.
"""

from __future__ import annotations

import hashlib
import tomllib
from pathlib import Path
from typing import Any

import tomli_w

from motorlab import jobs
from motorlab.errors import MotorlabError
from motorlab.launcher import trial
from motorlab.recipes import SEEDS, parse_recipe, set_fields, step_fields
from motorlab.stepkind import StepKind
from motorlab.sweeps.grid import labels
from motorlab.sweeps.targets import RecipeTarget, StepTarget


def command_trials(target: StepTarget, settings: list[dict[str, Any]], seeds: list[int], sweep_dir: Path,
                   threads: dict[str, str], flag: str = "--grid", hyperparams: set[str] = frozenset()
                   ) -> list[dict[str, Any]]:
    """Trials of a step kind's target: each its setting's fields, its seed and its run folder.
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


def recipe_variant(data: dict[str, Any], setting: dict[str, Any], seed: int, source: str,
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


def recipe_trials(target: RecipeTarget, settings: list[dict[str, Any]], seeds: list[int], sweep_dir: Path,
                  threads: dict[str, str], flag: str = "--grid") -> list[dict[str, Any]]:
    """Trials of a whole study: each runs `motorlab run` on a variant of the recipe written
    to <sweep>/recipes/, with the target's fields and the setting applied and all seeds set to the
    trial's (`flag`: the option the settings came from, named in errors)."""
    path = target.path
    try:
        data = target.data(tomllib.loads(path.read_text()), str(path), "--set")
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
