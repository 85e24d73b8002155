"""The processes of one tuning trial: its sampled settings as sweep trials (one per seed), run
on the local pool while this process watches their metrics.

A tuning trial reuses the sweep's trials, so each seed is the same `python -m motorlab ...`
command line a user could type, writing one run folder; only the folder differs:
DIR/trials/<number>/seed<k>/ (and its log DIR/trials/<number>/logs/seed<k>.log).
"""

from __future__ import annotations

import shlex
import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from motorlab.errors import MotorlabError, did_you_mean
from motorlab.sweeps import backends
from motorlab.sweeps.trials import (
    ALGORITHM_FIELDS,
    CONFIG,
    HYPERPARAMETERS,
    algorithm,
    check_hyperparameters,
    command_of,
    command_trials,
    hyperparameter_value,
    parse_options,
    recipe_path,
    recipe_trials,
    takes_hyperparameters,
)
from motorlab.tuning.space import Dist

FLAG = "--space"  # where a trial's settings come from, as errors name it

if TYPE_CHECKING:
    from typer.core import TyperGroup


class Planner:
    """Turns sampled values into the trial processes of a command line or a recipe."""

    def __init__(self, target: str, space: dict[str, Dist], commands: TyperGroup | None, threads: dict[str, str]):
        self.target = target
        self.space = space
        self.commands = commands
        self.threads = threads
        self.recipe = recipe_path(target)
        self.options = set() if self.recipe else _options(commands, target)

    def check(self) -> None:
        """Plan (not run) trials with every choice and both bounds of every key, so that a key the
        command or recipe does not have, an SB3 hyperparameter its algorithm does not have, or a
        value its command line cannot parse (a word for an integer option), fails before the
        search starts (before its database is made) rather than as failed trials. (Values the
        command parses but its settings refuse, such as history 0, fail in the trial.)

        Raises:
            MotorlabError: one line naming the --space key and the fix.
        """
        edges = {k: list(d.choices) if d.kind == "choice" else
                 [str(int(v)) if d.kind == "int" else repr(v) for v in (d.low, d.high)] for k, d in self.space.items()}
        if self.recipe is None:
            self._check_passed_on(edges)
        with tempfile.TemporaryDirectory() as scratch:
            base = {k: values[0] for k, values in edges.items()}
            self.plan(base, [0], Path(scratch))
            for key, values in edges.items():
                for value in values[1:]:
                    self.plan({**base, key: value}, [0], Path(scratch))

    def passes_on(self, dist: Dist) -> bool:
        """The key goes to the command line as `--set KEY=VALUE` (an SB3 hyperparameter), not as an option."""
        return dist.is_hyperparam or dist.name.replace("_", "-") not in self.options

    def _check_passed_on(self, edges: dict[str, list[str]]) -> None:
        """The keys passed on as SB3 hyperparameters, with their edge values, against the command and
        the algorithm its target trains, each named in its own error. A name that is no option gets
        the close options too: it may be a misspelt one. (When the space searches what chooses the
        algorithm, --algo or a preset, each planned trial's command line is checked as it is planned.)"""
        passed = [d for d in self.space.values() if self.passes_on(d)]
        if not passed:
            return
        if self.commands is None:
            raise ValueError("a command-line target needs the motorlab command group to check it against")
        cmd, step_kind, head, args = command_of(self.commands, self.target)
        name = " ".join(head)
        options = sorted(f"--{o}" for o in self.options)
        if HYPERPARAMETERS not in options:
            d = passed[0]
            flag = "--" + d.name.replace("_", "-")
            what = (f"`motorlab {name}` takes no SB3 hyperparameters" if d.is_hyperparam else
                    f"`motorlab {name}` has no option {flag}{did_you_mean(flag, options)}")
            raise MotorlabError(f"--space {d.key}: {what}; see motorlab {name} --help.")
        searched = {d.name for d in self.space.values() if not self.passes_on(d)}
        if step_kind is None or searched & {*ALGORITHM_FIELDS, CONFIG}:
            return
        where = f"motorlab tune {self.target!r}"
        algo = algorithm(step_kind, parse_options(cmd, [*args, "--seed", "0", "--out", "x"], where), where)
        for d in passed:
            flag = "--" + d.name.replace("_", "-")
            problems = [] if d.is_hyperparam else [f"`motorlab {name}` has no option {flag}{did_you_mean(flag, options)}"]
            if algo is None or not takes_hyperparameters(algo):
                problems.append(f"{str(algo).upper()} takes no SB3 hyperparameters (--set)")
                raise MotorlabError(f"--space {d.key}: {'; '.join(problems)}; see motorlab {name} --help.")
            for value in edges[d.key]:
                try:
                    check_hyperparameters(algo, {d.name: hyperparameter_value(value)})
                except MotorlabError as e:
                    raise MotorlabError(f"--space {d.key}: {'; '.join([*problems, str(e)])}") from None

    def plan(self, values: dict[str, str], seeds: list[int], trial_dir: Path) -> list[dict[str, Any]]:
        """One sweep trial per seed, with run folders trial_dir/seed<k>/.

        Raises:
            MotorlabError: a key the command (or recipe) does not have, a value it refuses.
        """
        if self.recipe is not None:
            planned = recipe_trials(self.recipe, [values], seeds, trial_dir, self.threads, flag=FLAG)
        else:
            command, options = self.target, {}
            for key, value in values.items():
                dist = self.space[key]
                if self.passes_on(dist):
                    command += f" {HYPERPARAMETERS} " + shlex.quote(f"{dist.name}={value}")  # an SB3 hyperparameter
                else:
                    options[dist.name] = value
            if self.commands is None:
                raise ValueError("a command-line target needs the motorlab command group to check it against")
            planned = command_trials(self.commands, command, [options], seeds, trial_dir, self.threads, flag=FLAG)
        return [_relocated(t, trial_dir / f"seed{t['seed']}", trial_dir / "logs" / f"seed{t['seed']}.log")
                for t in planned]


def _options(commands: TyperGroup | None, target: str) -> set[str]:
    """The long option names (without --) of the command a command line runs ("" if unknown:
    then command_trials reports the unknown command)."""
    try:
        words = shlex.split(target)
    except ValueError:
        return set()
    words = words[1:] if words[:1] == ["motorlab"] else words
    cmd: Any = commands
    for word in words[:2]:
        sub = getattr(cmd, "commands", {}).get(word)
        if sub is None:
            break
        cmd = sub
    if cmd is commands or cmd is None:
        return set()
    return {o[2:] for p in cmd.params for o in [*getattr(p, "opts", []), *getattr(p, "secondary_opts", [])]
            if o.startswith("--")}


def _relocated(t: dict[str, Any], run_dir: Path, log: Path) -> dict[str, Any]:
    """A sweep trial moved to another run folder (its command line's --out, resume line and log too)."""
    old, new = t["run_dir"], str(run_dir.resolve())

    def swap(argv: list[str] | None) -> list[str] | None:
        return [new if a == old else a for a in argv] if argv else argv

    return {**t, "argv": swap(t["argv"]), "resume_argv": swap(t["resume_argv"]), "run_dir": new,
            "log": str(log.resolve())}


class SeedRuns:
    """A trial's seed processes, run by the sweep's local pool in a helper thread, so that this
    (main) thread can watch their progress, receive Ctrl-C, and stop them early (pruning)."""

    def __init__(self, runs: list[dict[str, Any]], max_parallel: int):
        self.runs = runs
        self.exit_codes: dict[str, int] = {}
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, args=(max_parallel,), daemon=True)

    def _work(self, max_parallel: int) -> None:
        try:
            backends.run_local(self.runs, max_parallel, lambda t, rc, _s: self.exit_codes.__setitem__(t["name"], rc),
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
        return [f"{t['name']} exit {self.exit_codes.get(t['name'], '?')}: {backends.last_line(Path(t['log']))}"
                for t in self.runs if self.exit_codes.get(t["name"]) != 0]


def run_dirs(runs: list[dict[str, Any]]) -> list[Path]:
    return [Path(t["run_dir"]) for t in runs]


def require_target(target: str) -> None:
    if not target.strip():
        raise MotorlabError("give a command line in quotes or a recipe to tune, e.g. "
                            "motorlab tune \"train InvertedPendulum-v5\" --space lr=loguniform:1e-5,1e-2 ...")
