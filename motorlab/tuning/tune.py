"""`motorlab tune TARGET --space KEY=DIST ... --trials N --seeds K --objective METRIC`: the search,
then its outputs, then the best settings on K fresh seeds.

    DIR/study.db                 the Optuna study (SQLite, unless --storage names another database)
    DIR/trials/<n>/seed<k>/      each trial's run folders; DIR/trials/<n>/logs/ their output
    DIR/fresh/seed<k>/           the best settings re-run on seeds the search never used
    DIR/trials.csv, best.toml, plots/*.png, summary.json, config.toml, report.html
    DIR/best_recipe.toml         a recipe target: the recipe with the best settings (motorlab run FILE)

The fresh seeds' numbers sit beside the search's in summary.json and the table: the winner's
search number is the best of many and so flatters it; the fresh one does not.
"""

from __future__ import annotations

import fcntl
import time
from pathlib import Path
from typing import Any

import optuna
from optuna.trial import TrialState
from rich.console import Console

from motorlab import launcher, trackers
from motorlab.errors import MotorlabError, mask_secrets
from motorlab.launcher import is_finished
from motorlab.report.html import build_report
from motorlab.report.tables import plain_table, rich_table
from motorlab.runs import (
    SUMMARY,
    atomic_write_text,
    claim_folder,
    folder_mode,
    prepare_run_dir,
    read_json,
    refuse_finished,
    run_path,
    write_config,
)
from motorlab.settings import MAX_SEEDS
from motorlab.sweeps.targets import Target
from motorlab.tuning import outputs
from motorlab.tuning.objective import Objective, steps_run
from motorlab.tuning.search import TuneSpec, default_parallel, run_search, study_name
from motorlab.tuning.space import Dist
from motorlab.tuning.trials import Planner, SeedRuns

FRESH_SEED = 1000  # the fresh seeds are FRESH_SEED.. (or K.. when K is larger): never a search seed


def make_spec(target: Target, space: dict[str, Dist], trials: int, seeds: int, objective: str, direction: str | None,
              out: Path | None, storage: str | None, name: str | None, sampler: str, pruner: str, prune_startup: int,
              report_every: int, max_parallel: int | None, fresh_seeds: int | None, backend: str = "local",
              address: str | None = None, sampler_seed: int | None = None) -> TuneSpec:
    """The search's settings, checked.

    Raises:
        MotorlabError: bad spaces, counts or directions, --address without --backend ray, no Ray
            cluster at --address (before anything is written).
    """
    parsed = space
    if trials < 1:
        raise MotorlabError(f"--trials {trials}: give at least 1.")
    if not 1 <= seeds <= MAX_SEEDS:
        raise MotorlabError(f"--seeds {seeds}: give between 1 and {MAX_SEEDS:,} seeds (seeds 0..K-1).")
    if report_every < 1:
        raise MotorlabError(f"--report-every {report_every}: give at least 1 env step.")
    if prune_startup < 0:
        raise MotorlabError(f"--prune-startup {prune_startup}: give 0 or more.")
    if fresh_seeds is not None and fresh_seeds < 0:
        raise MotorlabError(f"--fresh-seeds {fresh_seeds}: give 0 (no re-evaluation) or more.")
    goal = Objective.make(objective, direction)
    launcher.check_execution(backend, address, max_parallel)  # last: it may try to reach the cluster
    folder = run_path(out, "tune").resolve()
    return TuneSpec(target=target.text, space=parsed, objective=goal, trials=trials, seeds=seeds, out=folder,
                    storage=storage or f"sqlite:///{folder / 'study.db'}",
                    study_name=name or study_name(target.text, parsed, goal, seeds), sampler=sampler,
                    sampler_seed=sampler_seed, pruner=pruner,
                    prune_startup=prune_startup, report_every=report_every,
                    max_parallel=default_parallel(max_parallel), fresh_seeds=seeds if fresh_seeds is None else fresh_seeds,
                    backend=backend, address=address, cluster_parallel=max_parallel if backend == "ray" else None)


def run_tune(spec: TuneSpec, target: Target, console: Console | None = None) -> dict[str, Any]:
    """Search, write the outputs, re-run the best on fresh seeds. Returns the summary (also summary.json).

    Raises:
        MotorlabError: a key the target does not have, an unreachable storage, an objective the
            runs' summary.json lacks, trials that keep failing.
    """
    console = console or Console(stderr=True)
    threads = ({"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"} if spec.max_parallel != 1 or spec.backend == "ray"
               else {})
    planner = Planner(target, spec.space, threads)
    planner.check()
    with trackers.also(planner.track, "the tune's target"):  # checked before anything is written
        return _search(spec, planner, console)


def _search(spec: TuneSpec, planner: Planner, console: Console) -> dict[str, Any]:
    """The search, checked and planned, run into its folder; then its outputs."""
    # the default storage, a SQLite file in --out, may be there before the search is (a study made for it)
    database = frozenset({"study.db", "study.db-journal", "study.db-wal", "study.db-shm"}) \
        if spec.storage == f"sqlite:///{spec.out / 'study.db'}" else frozenset()
    refuse_finished(spec.out, resumable=True, kind="tune", inputs=database)  # a finished search: --resume or replaced
    if folder_mode() == "overwrite":
        prepare_run_dir(spec.out, "tune", resumable=True)  # the old folder (and its study.db) aside until this search ends
    else:  # marked as a search's folder, not locked: processes sharing the study's database share it too
        claim_folder(spec.out, "tune", inputs=database)
    config = mask_secrets({"tune": spec.target, "space": {k: d.describe() for k, d in spec.space.items()},
                           "objective": spec.objective.key, "direction": spec.objective.direction,
                           "trials": spec.trials, "seeds": spec.seeds, "storage": spec.storage,  # no password in files
                           "study_name": spec.study_name, "sampler": spec.sampler, "pruner": spec.pruner,
                           **({"sampler_seed": spec.sampler_seed} if spec.sampler_seed is not None else {})})
    # --track: the search is a parent run, each seed's run nests under it
    with trackers.parent("tune", spec.out, config):
        t0 = time.perf_counter()
        if spec.backend == "ray":
            from motorlab.tuning.ray_search import run_ray_search  # Ray, imported only when asked for

            study = run_ray_search(spec, planner, console)
        else:
            study = run_search(spec, planner, console)
        spec.out.mkdir(parents=True, exist_ok=True)
        write_config(spec.out, config)
        summary = write_results(spec, study, planner, console, time.perf_counter() - t0)
        trackers.outputs(spec.out, summary)  # the parent run gets trials.csv, best.toml, plots, ...
    return summary


def _best(study: optuna.Study) -> optuna.trial.FrozenTrial | None:
    return study.best_trial if study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)) else None


def fresh_evaluation(spec: TuneSpec, planner: Planner, settings: dict[str, str], console: Console) -> outputs.Fresh | None:
    """The best settings on `spec.fresh_seeds` seeds the search never used (kept when already run
    with the same command lines). Only one process sharing the folder runs it (a file lock)."""
    if spec.fresh_seeds == 0:
        return None
    first = max(FRESH_SEED, spec.seeds)
    seeds = list(range(first, first + spec.fresh_seeds))
    runs = planner.plan(settings, seeds, spec.out / "fresh")
    lock_path = spec.out / "fresh.lock"
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    with open(lock_path, "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            console.print("fresh seeds: another process re-evaluates the best settings; see its summary.json.")
            return None
        todo = [t for t in runs if not is_finished(t)]
        if todo:
            console.print(f"fresh seeds: the best settings on seeds {seeds[0]}..{seeds[-1]}")
            group = SeedRuns(todo, spec.max_parallel).start()
            group.wait()
            if failed := group.failures():
                raise MotorlabError(f"the re-evaluation on fresh seeds failed: {failed[0]}")
    scores = [spec.objective.score(read_json(Path(t["run_dir"]) / SUMMARY)) for t in runs]
    return outputs.Fresh(seeds, scores, spec.objective)



def write_results(spec: TuneSpec, study: optuna.Study, planner: Planner, console: Console, wall: float) -> dict[str, Any]:
    trials = outputs.shown_trials(study)
    best = _best(study)
    fresh = None
    if best is not None:
        settings = best.user_attrs.get("settings") or {k: str(v) for k, v in best.params.items()}
        fresh = fresh_evaluation(spec, planner, settings, console)
        fields = outputs.preset_fields(settings, spec.space, None if planner.recipe else planner.options)
        best_toml = spec.out / "best.toml"
        header = [f"best settings of motorlab tune ({spec.study_name}), trial {best.number}: "
                  f"{spec.objective.key} {spec.objective.describe(outputs.seed_scores(best), outputs.number)} "
                  f"over seeds {', '.join(map(str, spec.seed_list))}"]
        if not planner.recipe:
            header.append("reproduce a seed: " + outputs.reproduce_line(spec.target, best_toml, 0))
        outputs.write_best_toml(best_toml, fields, header)
        if planner.recipe:  # a recipe's best settings as a recipe: the best trial's own, at its seed 0
            outputs.write_best_recipe(spec.out / "best_recipe.toml", spec.out / "trials" / str(best.number), header)
    outputs.write_trials_csv(trials, spec.space, spec.out / "trials.csv")
    rows = outputs.table_rows(trials, spec.space, best, fresh, spec.objective)
    title = (f"tune {spec.objective.key} ({spec.objective.direction}): each trial's "
             f"{spec.objective.statistic(spec.seeds)} over {spec.seeds} seeds")
    atomic_write_text(spec.out / "table.txt", plain_table(outputs.COLUMNS, mask_secrets(rows)))
    console.print(rich_table(title, outputs.COLUMNS, rows, left=("trial", "state", "settings", "per seed")))
    outputs.write_plots(study, spec.space, spec.out / "plots", title)
    by_state = {s.name.lower(): sum(t.state == s for t in trials) for s in TrialState}
    saved = sum(t.user_attrs.get("env_steps_saved", 0) for t in trials)
    steps = sum(t.user_attrs.get("env_steps", 0) for t in trials)
    summary: dict[str, Any] = {
        "tune": mask_secrets(spec.target), "objective": spec.objective.key, "direction": spec.objective.direction,
        "study_name": spec.study_name, "storage": mask_secrets(spec.storage), "trials": spec.trials, "seeds": spec.seed_list,
        "n_trials": {k: v for k, v in by_state.items() if v}, "best_trial": best.number if best else None,
        "best_value": best.value if best else None, "best_params": best.params if best else None,
        "best_seed_values": best.user_attrs.get("seed_values") if best else None,
        "best_seed_censored": [c for _, c in outputs.seed_scores(best)] if best else None,
        "best_text": spec.objective.describe(outputs.seed_scores(best), outputs.number) if best else None,
        "statistic": spec.objective.statistic(spec.seeds),
        "env_steps_run": steps + (sum(steps_run(spec.out / "fresh" / f"seed{s}") for s in fresh.seeds) if fresh else 0),
        "env_steps_saved_by_pruning": saved, "wall_seconds": round(wall, 2),
    }
    if fresh is not None:
        summary.update(fresh.to_summary())
    outputs.write_tune_summary(spec.out, summary)
    build_report([spec.out], spec.out / "report.html")
    summary["tune_dir"] = str(spec.out)
    return summary
