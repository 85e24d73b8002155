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

from motorlab.errors import MotorlabError
from motorlab.sweeps import backends
from motorlab.sweeps.trials import command_trials, recipe_path, recipe_trials
from motorlab.tuning.space import Dist

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
        command or recipe does not have, or a value its command line cannot parse (a word for an
        integer option), fails before the search starts rather than as failed trials. (Values the
        command parses but its settings refuse, such as history 0, fail in the trial.)"""
        edges = {k: list(d.choices) if d.kind == "choice" else
                 [str(int(v)) if d.kind == "int" else repr(v) for v in (d.low, d.high)] for k, d in self.space.items()}
        with tempfile.TemporaryDirectory() as scratch:
            base = {k: values[0] for k, values in edges.items()}
            self.plan(base, [0], Path(scratch))
            for key, values in edges.items():
                for value in values[1:]:
                    self.plan({**base, key: value}, [0], Path(scratch))

    def plan(self, values: dict[str, str], seeds: list[int], trial_dir: Path) -> list[dict[str, Any]]:
        """One sweep trial per seed, with run folders trial_dir/seed<k>/.

        Raises:
            MotorlabError: a key the command (or recipe) does not have, a value it refuses.
        """
        if self.recipe is not None:
            planned = recipe_trials(self.recipe, [values], seeds, trial_dir, self.threads)
        else:
            command, options = self.target, {}
            for key, value in values.items():
                dist = self.space[key]
                if dist.is_hyperparam or dist.name.replace("_", "-") not in self.options:
                    command += " --set " + shlex.quote(f"{dist.name}={value}")  # an SB3 hyperparameter
                else:
                    options[dist.name] = value
            if self.commands is None:
                raise ValueError("a command-line target needs the motorlab command group to check it against")
            planned = command_trials(self.commands, command, [options], seeds, trial_dir, self.threads)
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
