"""`motorlab tune`: the Optuna search over a command's (or recipe's) settings, judged on several seeds.

Each Optuna trial samples settings, runs K seeds of them as processes (the sweep's trials),
reports intermediate numbers while they train (see objective.py) so a pruner can stop a
hopeless trial, and scores the trial over its seeds (objective.Objective.combine: the IQM, or
for steps to success the restricted mean, unsolved seeds at their budgets).

The study lives in a database (SQLite DIR/study.db by default), under a name derived from
what is searched, so the same command resumes it and several processes (or machines sharing
the database) work on one search:

- `--trials N` counts COMPLETE and PRUNED trials over every process. A process starts a trial
  only while fewer than N trials are finished or running, and a trial that finds N trials ahead
  of it (two processes asked at once) gives way at once, before it runs anything.
- A trial whose process was killed stays RUNNING until its heartbeat is stale, then Optuna
  marks it FAIL and RetryHeartbeatStaleTrialCallback queues its settings again; a trial stopped with
  Ctrl-C is marked FAIL at once and queued again by the next `motorlab tune` of the study.
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import optuna
from optuna.pruners import BasePruner, HyperbandPruner, MedianPruner, NopPruner
from optuna.storages import RDBStorage, RetryHeartbeatStaleTrialCallback
from optuna.trial import FrozenTrial, TrialState
from sqlalchemy.exc import IntegrityError, OperationalError

from motorlab.errors import MotorlabError, mask_secrets, mask_url, redact
from motorlab.runs import SUMMARY, read_json
from motorlab.tuning import outputs
from motorlab.tuning.objective import Objective, Reporter, budget_of, steps_run, trial_horizon
from motorlab.tuning.space import Dist
from motorlab.tuning.trials import Planner, SeedRuns, run_dirs

if TYPE_CHECKING:
    from rich.console import Console

POLL_SECONDS = 1.0
HEARTBEAT_SECONDS = 10  # a killed process's trial is marked failed (and retried) after GRACE_SECONDS
GRACE_SECONDS = 30
MAX_RETRIES = 2
SCHEMA_ATTEMPTS = 3  # opening a new database that another process is creating at the same moment
MAX_FAILURES_IN_A_ROW = 3  # trials whose processes fail; then the search stops with the cause
SAMPLERS = ("tpe", "random", "cmaes")
PRUNERS = ("median", "hyperband", "none")
COUNTED = (TrialState.COMPLETE, TrialState.PRUNED)


@dataclass(frozen=True)
class TuneSpec:
    """One search, as the command line gives it."""

    target: str
    space: dict[str, Dist]
    objective: Objective
    trials: int
    seeds: int
    out: Path
    storage: str
    study_name: str
    sampler: str = "tpe"
    sampler_seed: int | None = None  # the sampler's random seed: the same search samples the same settings
    pruner: str = "median"
    prune_startup: int = 5
    report_every: int = 1000
    max_parallel: int = 1
    fresh_seeds: int = 0
    backend: str = "local"  # or "ray": Ray Tune (ray_search.py), on the cluster at `address` or a Ray started here
    address: str | None = None
    cluster_parallel: int | None = None  # ray: seed processes at once on the cluster (None: as many as its CPUs fit)

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seeds))


def study_name(target: str, space: dict[str, Dist], objective: Objective, seeds: int) -> str:
    """A name derived from what is searched: the same command finds its study again; a search of
    other keys, another objective or other seeds in the same database gets a study of its own."""
    text = json.dumps({"target": target, "space": {k: d.describe() for k, d in space.items()},
                       "objective": objective.key, "direction": objective.direction, "seeds": seeds}, sort_keys=True)
    return "motorlab-tune-" + hashlib.sha256(text.encode()).hexdigest()[:10]


class LatestMedianPruner(MedianPruner):
    """Optuna's median rule on the trial's latest number rather than its best so far.

    MedianPruner compares a trial's best intermediate value over all steps; a steps-to-success
    lower bound only grows, so its best is its first and it would never be pruned. The latest
    number is the one that says how far behind the trial is at this step."""

    def prune(self, study: optuna.Study, trial: FrozenTrial) -> bool:
        step = trial.last_step
        if step is None:
            return False
        latest = copy.copy(trial)  # shallow: the new dict leaves the trial's own values alone
        latest.intermediate_values = {step: trial.intermediate_values[step]}
        return super().prune(study, latest)


def make_pruner(spec: TuneSpec) -> BasePruner:
    if spec.pruner == "median":
        return LatestMedianPruner(n_startup_trials=spec.prune_startup, n_warmup_steps=0)
    if spec.pruner == "hyperband":
        return HyperbandPruner(min_resource=spec.report_every, max_resource="auto", reduction_factor=3)
    return NopPruner()


def make_sampler(name: str, seed: int | None = None) -> optuna.samplers.BaseSampler:
    """Raises: MotorlabError for an unknown sampler, or cmaes without its package."""
    if name == "tpe":
        return optuna.samplers.TPESampler(seed=seed)
    if name == "random":
        return optuna.samplers.RandomSampler(seed=seed)
    if name == "cmaes":
        try:
            import cmaes  # noqa: F401 - Optuna's CMA-ES sampler needs it
        except ImportError:
            raise MotorlabError("--sampler cmaes needs the cmaes package: pip install cmaes") from None
        return optuna.samplers.CmaEsSampler(seed=seed, warn_independent_sampling=False)
    raise MotorlabError(f"--sampler {name!r}: choose one of {', '.join(SAMPLERS)}.")


def open_study(spec: TuneSpec) -> optuna.Study:
    """Create the study, or load it when it exists (resume; another process's search).

    Raises:
        MotorlabError: the storage URL cannot be opened (one line).
    """
    if spec.pruner not in PRUNERS:
        raise MotorlabError(f"--pruner {spec.pruner!r}: choose one of {', '.join(PRUNERS)}.")
    sampler = make_sampler(spec.sampler, spec.sampler_seed)
    optuna.logging.set_verbosity(optuna.logging.ERROR)  # motorlab says what happened
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
    try:
        study = optuna.create_study(storage=open_storage(spec), study_name=spec.study_name,
                                    direction=spec.objective.direction, sampler=sampler, pruner=make_pruner(spec),
                                    load_if_exists=True)
        if spec.sampler_seed is not None and (n := len(study.get_trials(deepcopy=False))):
            # a resumed seeded search goes on from where its sampler was, not from its first samples again
            study.sampler = make_sampler(spec.sampler, spec.sampler_seed + n)
        return study
    except (ImportError, ValueError) as e:  # the driver's or SQLAlchemy's words may quote the URL: masked
        raise MotorlabError(f"--storage {mask_url(spec.storage)}: {redact(_first_line(e), spec.storage)} (give a "
                            "database URL such as sqlite:///runs/tune/study.db or postgresql://user@host/db, with "
                            "its driver installed).") from None
    except Exception as e:  # noqa: BLE001 - SQLAlchemy's connection errors have no common public base here
        raise MotorlabError(f"cannot open the study storage {mask_url(spec.storage)}: "
                            f"{redact(_first_line(e), spec.storage)}") from None


def open_storage(spec: TuneSpec) -> RDBStorage:
    """The study's database, with heartbeats: a trial whose process died is failed and retried."""
    # several processes on one SQLite file wait for each other's writes instead of failing at once
    engine = {"connect_args": {"timeout": 60}} if spec.storage.startswith("sqlite") else None
    for attempt in range(SCHEMA_ATTEMPTS):
        try:
            return RDBStorage(spec.storage, engine_kwargs=engine, heartbeat_interval=HEARTBEAT_SECONDS,
                              grace_period=GRACE_SECONDS,
                              heartbeat_stale_trial_callback=RetryHeartbeatStaleTrialCallback(max_retry=MAX_RETRIES))
        except (IntegrityError, OperationalError) as e:
            # two processes creating a new database at once: both create its tables and write its
            # schema version, one loses the race ("UNIQUE constraint failed", "table ... already
            # exists"); the schema is there now, so opening it again succeeds
            racing = isinstance(e, IntegrityError) or "already exists" in str(e)
            if not racing or attempt == SCHEMA_ATTEMPTS - 1:
                raise
            time.sleep(0.5)
    raise AssertionError("unreachable")


def _first_line(e: BaseException) -> str:
    text = str(getattr(e, "orig", None) or e).strip()
    return text.splitlines()[0] if text else type(e).__name__


class TrialFailed(MotorlabError):
    """A trial's seed processes failed; the search goes on (a few in a row stop it)."""


class GiveWay(Exception):
    """This trial found `--trials` trials ahead of it: another process asked at the same time."""


@dataclass
class Counters:
    """What this process's trials did, for its messages."""

    failures_in_a_row: int = 0
    done: list[int] = field(default_factory=list)


def _ahead(study: optuna.Study, number: int) -> int:
    states = (*COUNTED, TrialState.RUNNING)
    return sum(t.number < number for t in study.get_trials(deepcopy=False, states=states))


def counted(study: optuna.Study) -> int:
    return len(study.get_trials(deepcopy=False, states=COUNTED))


def retry_interrupted(study: optuna.Study) -> int:
    """Queue again the settings of trials a Ctrl-C stopped (marked FAIL, "interrupted") that no
    trial retries yet; returns how many."""
    trials = study.get_trials(deepcopy=False)
    retried = {n for t in trials for n in t.system_attrs.get("retry_history", [])}
    queued = 0
    for t in trials:
        if t.state == TrialState.FAIL and t.user_attrs.get("interrupted") and t.number not in retried:
            RetryHeartbeatStaleTrialCallback(max_retry=MAX_RETRIES)(study, t)
            queued += 1
    return queued


class Search:
    """The objective Optuna calls, one trial at a time, in this process."""

    def __init__(self, spec: TuneSpec, planner: Planner, console: Console):
        self.spec = spec
        self.planner = planner
        self.console = console
        self.counters = Counters()

    def __call__(self, trial: optuna.Trial) -> float:
        study = trial.study
        if _ahead(study, trial.number) >= self.spec.trials:
            trial.set_user_attr("gave_way", True)
            study.stop()
            raise GiveWay
        trial.set_user_attr("interrupted", False)
        values = {k: d.suggest(trial) for k, d in self.spec.space.items()}
        runs = self.planner.plan(values, self.spec.seed_list, self.spec.out / "trials" / str(trial.number))
        dirs = run_dirs(runs)
        trial.set_user_attr("run_dirs", [str(d) for d in dirs])
        trial.set_user_attr("settings", values)
        shown = ", ".join(f"{k}={v}" for k, v in values.items())
        self.console.print(f"  trial {trial.number}: {shown} ({len(runs)} seed{'s' * (len(runs) != 1)})")
        seeds = SeedRuns(runs, self.spec.max_parallel).start()
        reporter = Reporter(self.spec.objective, self.spec.report_every, dirs)
        try:
            while seeds.running():
                seeds.join(POLL_SECONDS)
                if _report(trial, reporter.reached()) and trial.should_prune():
                    seeds.stop()
                    self._pruned(trial, dirs, reporter.last_step)
            seeds.wait()
        except KeyboardInterrupt:
            seeds.stop()
            trial.set_user_attr("interrupted", True)
            raise
        failed = seeds.failures()
        if failed:
            self.counters.failures_in_a_row += 1
            trial.set_user_attr("error", mask_secrets(failed[0]))
            message = f"trial {trial.number} failed: {failed[0]}"
            self.console.print(f"  [red]✗[/red] {message}")
            if self.counters.failures_in_a_row >= MAX_FAILURES_IN_A_ROW:
                raise MotorlabError(f"{MAX_FAILURES_IN_A_ROW} trials in a row failed; the last: {message}")
            raise TrialFailed(message)
        self.counters.failures_in_a_row = 0
        scores = [self.spec.objective.score(read_json(d / SUMMARY)) for d in dirs]
        _report(trial, reporter.filled(trial_horizon(dirs)))
        value = self.spec.objective.combine([v for v, _ in scores])
        outputs.keep_seed_scores(trial, scores)
        trial.set_user_attr("env_steps", sum(steps_run(d) for d in dirs))
        self.counters.done.append(trial.number)
        self.console.print(f"  [green]✓[/green] trial {trial.number}: {outputs.trial_line(self.spec.objective, scores)}")
        return value

    def _pruned(self, trial: optuna.Trial, dirs: list[Path], step: int) -> None:
        run = sum(steps_run(d) for d in dirs)
        budget = sum(budget_of(d) or 0 for d in dirs)
        trial.set_user_attr("env_steps", run)
        trial.set_user_attr("env_steps_saved", max(0, budget - run))
        self.console.print(f"  [yellow]✂[/yellow] trial {trial.number} pruned at step {step:,} "
                           f"({max(0, budget - run):,} env steps saved)")
        raise optuna.TrialPruned


def _report(trial: optuna.Trial, numbers: list[tuple[int, float]]) -> bool:
    for step, value in numbers:
        trial.report(value, step)
    return bool(numbers)


def default_parallel(max_parallel: int | None) -> int:
    if max_parallel is not None and max_parallel < 1:
        raise MotorlabError(f"--max-parallel {max_parallel}: give at least 1.")
    return max_parallel or os.cpu_count() or 1


def resume_study(spec: TuneSpec, console: Console) -> tuple[optuna.Study, bool]:
    """Open (or resume) the study, queue its interrupted trials again and say where it stands.
    Returns the study and whether trials are left to start (fewer than `spec.trials` finished or running)."""
    study = open_study(spec)
    optuna.storages.fail_stale_trials(study)  # trials of a process that died: failed, and queued again
    queued = retry_interrupted(study)
    have = counted(study)
    running = len(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)))
    console.print(f"tune: study {spec.study_name} in {mask_url(spec.storage)}: {have} of {spec.trials} trials finished"
                  + (f", {running} running elsewhere" if running else "")
                  + (f", {queued} interrupted trial{'s' * (queued > 1)} queued again" if queued else ""))
    return study, have + running < spec.trials


def run_search(spec: TuneSpec, planner: Planner, console: Console) -> optuna.Study:
    """Open (or resume) the study and run trials until `spec.trials` are COMPLETE or PRUNED
    over every process sharing it. Returns the study."""
    study, todo = resume_study(spec, console)
    if not todo:
        return study
    search = Search(spec, planner, console)

    def enough(study: optuna.Study, _trial: FrozenTrial) -> None:
        # this process's trial has ended: the RUNNING ones are other processes', which count too
        if counted(study) + len(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))) >= spec.trials:
            study.stop()

    try:
        study.optimize(search, n_trials=None, callbacks=[enough], catch=(TrialFailed, GiveWay),
                       gc_after_trial=False, show_progress_bar=False)
    except KeyboardInterrupt:
        console.print("tune interrupted: finished trials are kept; run the same command again to resume.")
        raise
    return study
