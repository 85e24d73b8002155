"""The processes of one tuning trial: its sampled settings as sweep trials (one per seed), run
on the local pool while this process watches their metrics.

A tuning trial reuses the sweep's trials, so each seed is the same `python -m motorlab ...`
command line a user could type, writing one run folder; only the folder differs:
DIR/trials/<number>/seed<k>/ (and its log DIR/trials/<number>/logs/seed<k>.log).
"""

from __future__ import annotations

import contextvars
import tempfile
import threading
from pathlib import Path
from typing import Any

from motorlab import launcher
from motorlab.commandline import json_or_text
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.sweeps.targets import (
    ALGORITHM_FIELDS,
    RecipeTarget,
    StepTarget,
    Target,
    check_hyperparameters,
    takes_hyperparameters,
)
from motorlab.sweeps.trials import command_trials, recipe_trials
from motorlab.tuning.space import Dist

FLAG = "--space"  # where a trial's settings come from, as errors name it


class Planner:
    """Turns sampled values into the trial processes of a command line or a recipe."""

    def __init__(self, target: Target, space: dict[str, Dist], threads: dict[str, str]):
        self.target = target  # read once, where it entered (motorlab.sweeps.targets)
        self.space = space
        self.threads = threads
        self.recipe = target if isinstance(target, RecipeTarget) else None
        self.command = target if isinstance(target, StepTarget) else None
        self.options = self.command.options() if self.command else set()
        self.track = self.command.track if self.command else ()  # the target's own --track: its trials', too

    def check(self) -> None:
        """Plan (not run) trials with every choice and both bounds of every key, so that a key the
        command or recipe does not have, an SB3 hyperparameter its algorithm does not have, or a
        value its settings refuse (a word for an integer option) fails before the search starts
        (before its database is made) rather than as failed trials.

        Raises:
            MotorlabError: one line naming the --space key and the fix.
        """
        edges = {k: list(d.choices) if d.kind == "choice" else [d.value(v) for v in (d.low, d.high)]
                 for k, d in self.space.items()}
        if self.command is not None:
            self._check_passed_on(edges)
        with tempfile.TemporaryDirectory() as scratch:
            base = {k: values[0] for k, values in edges.items()}
            self.plan(base, [0], Path(scratch))
            for key, values in edges.items():
                for value in values[1:]:
                    self.plan({**base, key: value}, [0], Path(scratch))

    def passes_on(self, dist: Dist) -> bool:
        """The key is an SB3 hyperparameter (train's `--set KEY=VALUE`), not one of the command's settings."""
        return dist.is_hyperparam or dist.name.replace("-", "_") not in self.options

    def _check_passed_on(self, edges: dict[str, list[Any]]) -> None:
        """The keys passed on as SB3 hyperparameters, with their edge values, against the command's
        settings and the algorithm its target trains, each named in its own error. A name that is no
        option gets the close options too: it may be a misspelt one. (When the space searches what
        chooses the algorithm, --algo or a preset, each planned trial is checked as it is planned.)"""
        passed = [d for d in self.space.values() if self.passes_on(d)]
        if not passed:
            return
        target = self.command
        options = sorted(f"--{o.replace('_', '-')}" for o in self.options)
        name = target.name
        if not target.takes_hyperparameters():
            d = passed[0]
            flag = "--" + d.name.replace("_", "-")
            what = (f"`motorlab {name}` takes no SB3 hyperparameters" if d.is_hyperparam else
                    f"`motorlab {name}` has no option {flag}{did_you_mean(flag, options)}")
            raise MotorlabError(f"--space {d.key}: {what}; see motorlab {name} --help.")
        searched = {d.name for d in self.space.values() if not self.passes_on(d)}
        if searched & set(ALGORITHM_FIELDS):
            return
        algo = getattr(target.settings(target.kind.with_seed(target.given.fields, 0), f"motorlab tune {target.text!r}"),
                       "algo", None)
        for d in passed:
            flag = "--" + d.name.replace("_", "-")
            problems = [] if d.is_hyperparam else [f"`motorlab {name}` has no option {flag}{did_you_mean(flag, options)}"]
            if algo is None or not takes_hyperparameters(algo):
                problems.append(f"{str(algo).upper()} takes no SB3 hyperparameters (--set)")
                raise MotorlabError(f"--space {d.key}: {'; '.join(problems)}; see motorlab {name} --help.")
            for value in edges[d.key]:
                try:
                    check_hyperparameters(algo, {d.name: json_or_text(value) if isinstance(value, str) else value})
                except MotorlabError as e:
                    raise MotorlabError(f"--space {d.key}: {'; '.join([*problems, str(e)])}") from None

    def plan(self, values: dict[str, Any], seeds: list[int], trial_dir: Path) -> list[dict[str, Any]]:
        """One sweep trial per seed, with run folders trial_dir/seed<k>/.

        Raises:
            MotorlabError: a key the command (or recipe) does not have, a value it refuses.
        """
        if self.recipe is not None:
            planned = recipe_trials(self.recipe, [values], seeds, trial_dir, self.threads, flag=FLAG)
        else:
            named = {self.space[k].name.replace("-", "_"): v for k, v in values.items()}
            hyper = {self.space[k].name.replace("-", "_") for k in values if self.passes_on(self.space[k])}
            planned = command_trials(self.command, [named], seeds, trial_dir, self.threads, flag=FLAG,
                                     hyperparams=hyper)
        return [_relocated(t, trial_dir / f"seed{t['seed']}", trial_dir / "logs" / f"seed{t['seed']}.log")
                for t in planned]


def _relocated(t: dict[str, Any], run_dir: Path, log: Path) -> dict[str, Any]:
    """A sweep trial moved to another run folder (its job's --out and its log too)."""
    new = str(run_dir.resolve())
    job = {**t["job"], "how": {**t["job"]["how"], "out": new}}
    return {**t, "job": job, "run_dir": new, "log": str(log.resolve())}


class SeedRuns:
    """A trial's seed processes, run by the sweep's local pool in a helper thread, so that this
    (main) thread can watch their progress, receive Ctrl-C, and stop them early (pruning)."""

    def __init__(self, runs: list[dict[str, Any]], max_parallel: int):
        self.runs = runs
        self.exit_codes: dict[str, int] = {}
        self._stop = threading.Event()
        self._error: BaseException | None = None
        # in a copy of this context: the trials' jobs get the search's tracking (its parent run)
        self._thread = threading.Thread(target=contextvars.copy_context().run, args=(self._work, max_parallel),
                                        daemon=True)

    def _work(self, max_parallel: int) -> None:
        try:
            launcher.run_local(self.runs, max_parallel, lambda t, rc, _s: self.exit_codes.__setitem__(t["name"], rc),
                               stop=self._stop)
        except KeyboardInterrupt:
            pass  # stopped on purpose: pruned or interrupted
        except BaseException as e:  # noqa: BLE001 - handed to the main thread
            self._error = e

    def start(self) -> SeedRuns:
        self._thread.start()
        return self

    def running(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout: float) -> None:
        """Wait until the seeds have ended, or at most `timeout` seconds (a poll that ends as soon as they do)."""
        self._thread.join(timeout)

    def stop(self) -> None:
        """Stop the running seeds as Ctrl-C would, and wait until they have."""
        self._stop.set()
        self._thread.join()

    def wait(self) -> None:
        self._thread.join()
        if self._error is not None:
            raise self._error

    def failures(self) -> list[str]:
        """One line per seed that did not finish: its exit status and last words."""
        return [f"{t['name']} exit {self.exit_codes.get(t['name'], '?')}: {launcher.last_line(Path(t['log']))}"
                for t in self.runs if self.exit_codes.get(t["name"]) != 0]


def run_dirs(runs: list[dict[str, Any]]) -> list[Path]:
    return [Path(t["run_dir"]) for t in runs]
