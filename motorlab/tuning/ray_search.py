"""`motorlab tune --backend ray [--address HOST:PORT]`: the same search on a Ray cluster (or a Ray
instance started here), through Ray Tune: Ray's OptunaSearch samples, a Tune scheduler stops
hopeless trials early, and each Tune trial runs the trial's K seeds as the local backend does
(ray_trial.SeedTrial, on a worker; the searcher and scheduler are in ray_study.py, on this driver).
This module imports Ray only when it runs (a missing Ray is the one-line pip hint).

    sampler     OptunaSearch with --sampler (tpe, random, cmaes; seeded by --sampler-seed), on the
                study in --storage itself
    scheduler   --pruner median (default): ASHA (Tune's AsyncHyperBandScheduler, one bracket);
                hyperband: ASHA with 3 brackets (asynchronous Hyperband); none: FIFO (no stopping).
                Tune's time is env steps (a trial's numbers come every --report-every steps);
                grace period GRACE_REPORTS × --report-every, reduction factor 3, max_t the target's
                --timesteps when it gives one. --prune-startup is the local median pruner's only.
    resources   a Tune trial asks for one CPU per seed (at most a node's CPUs) and runs its seeds at
                once; trials at once: --max-parallel seed processes // seeds, else as many as the
                cluster's CPUs fit (on a 2-core head with 2 seeds: one trial at a time)
    folders     OUT/trials/<n>/seed<k>/ as the local backend, <n> the study's trial number (given
                when Tune asks for the trial, in order); Tune's records (result.json with every
                number Tune got) in OUT/ray/tune/trial<n>/. Run folders are written by absolute
                path: every node must see --out at the same path (a shared file system).

The study lives in the database during the search (ray_study.StudySearch): each Tune trial is an
Optuna trial there, with its intermediate numbers at their env steps, its state (COMPLETE, PRUNED
when the scheduler stopped it, FAIL) and the user attributes of the local backend's trials, so
tune.write_results (trials.csv, best.toml, plots, fresh seeds) reads both backends alike.

Resume: the same command again counts the study's COMPLETE and PRUNED trials towards --trials
and runs only the rest; the sampler sees every earlier trial (it samples from the study itself),
and ASHA's rungs start with the earlier trials' numbers. Trials queued in the study run first:
those a Ctrl-C stopped (failed as interrupted), those of a driver that died (their heartbeats
stop), and any queued with Optuna's enqueue_trial.

The best settings' fresh seeds (tune.write_results) run on this machine's process pool.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import optuna

from motorlab import launcher
from motorlab.errors import MotorlabError, mask_url
from motorlab.tuning.search import COUNTED, TuneSpec, open_storage, resume_study

if TYPE_CHECKING:
    from rich.console import Console

    from motorlab.tuning.trials import Planner

GRACE_REPORTS = 3  # ASHA's grace period, in --report-every intervals: no trial is stopped before it
REDUCTION_FACTOR = 3  # as the local hyperband pruner's
HYPERBAND_BRACKETS = 3
UNBOUNDED = 10**15  # ASHA's max_t when the budget is not known here (each trial ends at its own budget)


def budget(spec: TuneSpec, planner: Planner) -> int | None:
    """The env-step budget of every trial, when the target's kind has one and the search does not vary
    it (a recipe target: None, each step has its own)."""
    target = planner.command
    if target is None or target.kind.BUDGET is None or any(d.name == target.kind.BUDGET for d in spec.space.values()):
        return None
    settings = target.settings(target.kind.with_seed(target.given.fields, 0), f"motorlab tune {spec.target!r}")
    return target.kind.planned_steps(settings)  # the kind's default when the target does not give it


def make_scheduler(spec: TuneSpec, planner: Planner, past: list[optuna.trial.FrozenTrial]) -> tuple[Any, str]:
    """Tune's scheduler for --pruner, and its name as messages show it."""
    from ray.tune.schedulers import FIFOScheduler

    from motorlab.tuning.ray_study import StudyASHA
    from motorlab.tuning.ray_trial import STEPS

    if spec.pruner == "none":
        return FIFOScheduler(), "FIFO (no early stopping)"
    grace = GRACE_REPORTS * spec.report_every
    brackets = HYPERBAND_BRACKETS if spec.pruner == "hyperband" else 1
    scheduler = StudyASHA(past, time_attr=STEPS, metric=spec.objective.key,
                          mode="max" if spec.objective.maximize else "min", max_t=max(grace, budget(spec, planner) or UNBOUNDED),
                          grace_period=grace, reduction_factor=REDUCTION_FACTOR, brackets=brackets,
                          stop_last_trials=False)  # a trial at its budget ends by itself, with its final numbers
    return scheduler, "ASHA" if brackets == 1 else "ASHA (async Hyperband)"


def _cpus_per_trial(ray: Any, seeds: int) -> int:
    """One CPU per seed, but no more than the largest node has (else the trial would never start)."""
    largest = max((int(n.get("Resources", {}).get("CPU", 0)) for n in ray.nodes() if n.get("Alive")), default=1)
    return max(1, min(seeds, largest))


def run_ray_search(spec: TuneSpec, planner: Planner, console: Console) -> optuna.Study:
    """Open (or resume) the study and run trials as Ray Tune trials until `spec.trials` are
    COMPLETE or PRUNED over every process sharing it. Returns the study.

    Raises:
        MotorlabError: Ray is not installed, no cluster answers at the address, the trials keep
            failing, or the objective is not in the runs' summary.json.
        KeyboardInterrupt: Ctrl-C (Tune stopped the running trials' seeds; they are queued again).
    """
    study, todo = resume_study(spec, console)
    if not todo:
        return study
    ray = launcher.init_ray(spec.address)
    from ray import tune
    from ray.tune.logger import JsonLoggerCallback

    from motorlab.tuning.ray_study import Heartbeat, StudySearch
    from motorlab.tuning.ray_trial import SeedTrial, dirname

    try:
        cpus = _cpus_per_trial(ray, spec.seeds)
        total = spec.cluster_parallel or int(ray.cluster_resources().get("CPU", cpus))
        at_once = max(1, total // cpus)
        scheduler, name = make_scheduler(spec, planner, study.get_trials(deepcopy=False, states=COUNTED))
        # the study's sampler: --sampler, seeded by --sampler-seed (and where a resumed search left it)
        search = StudySearch(spec, open_storage(spec), study.sampler, planner, console, parallel=cpus, scheduler=name)
        where = mask_url(spec.address) if spec.address else "a Ray instance started here"
        console.print(f"tune: Ray Tune at {where}: {name}, "
                      f"{at_once} trial{'s' * (at_once > 1)} at a time ({cpus} CPU{'s' * (cpus > 1)} each); "
                      f"Tune's records in {spec.out / 'ray'}")
        tuner = tune.Tuner(
            tune.with_resources(SeedTrial, {"cpu": cpus}),
            tune_config=tune.TuneConfig(search_alg=search, scheduler=scheduler, num_samples=-1,
                                        max_concurrent_trials=at_once, reuse_actors=False,
                                        trial_dirname_creator=dirname, trial_name_creator=dirname),
            run_config=tune.RunConfig(name="tune", storage_path=str(spec.out / "ray"), verbose=0,
                                      checkpoint_config=tune.CheckpointConfig(checkpoint_at_end=False),
                                      callbacks=[JsonLoggerCallback(), Heartbeat(search)]),
        )
        tuner.fit()
    finally:
        ray.shutdown()
    interrupted = search.settle()
    if search.fatal:
        raise MotorlabError(search.fatal)
    if interrupted or not search.finished:  # Tune stopped on Ctrl-C, and stopped the running seeds
        console.print("tune interrupted: finished trials are kept; run the same command again to resume.")
        raise KeyboardInterrupt
    return study
