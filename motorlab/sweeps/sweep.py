"""`motorlab sweep TARGET --seeds N [--grid key=v1,v2 ...]`: every seed of every setting, then
statistics across seeds.

    <sweep>/<setting>/seed<k>/   one run folder per trial (a study folder when TARGET is a recipe); <setting>
                                 is the grid values' slug and their hash, lr=3e-4-3ddbad7f (sweeps.grid.label)
    <sweep>/logs/<setting>-seed<k>.log   each trial's output
    <sweep>/recipes/             the recipe variant each trial ran (recipe targets)
    <sweep>/summary.json         "<setting>.<metric>_mean", "_iqm" (4+ seeds), "_iqm_ci_low"/"_mean_ci_low", ...
    <sweep>/aggregate.json       per-seed values, probability of improvement, performance profiles
    <sweep>/plots/*.png, table.txt, report.html
    <sweep>/ray/                 Ray Tune's own records (ray backend)

Run the same command again into the same --out to resume: finished trials are kept.

The target's own invocation options are applied (--config, --track: its trials are tracked there, nested
under the sweep) or refused in one line (--out, --overwrite, --resume: the sweep's); see sweeps.trials.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from motorlab import jobs, launcher, trackers
from motorlab.errors import MotorlabError, mask_secrets
from motorlab.launcher import is_finished
from motorlab.report import sweep_plots
from motorlab.report.html import build_report
from motorlab.report.tables import plain_table, rich_table
from motorlab.runs import (
    atomic_write_text,
    prepare_run_dir,
    read_json,
    refuse_finished,
    run_path,
    write_config,
    write_json,
    write_summary,
)
from motorlab.settings import MAX_SEEDS
from motorlab.stats import aggregate, trial_scores
from motorlab.sweeps.grid import settings
from motorlab.sweeps.targets import RecipeTarget, Target
from motorlab.sweeps.trials import command_trials, recipe_trials


def _seeds(seeds: int | list[int]) -> list[int]:
    if isinstance(seeds, int):
        if not 1 <= seeds <= MAX_SEEDS:
            raise MotorlabError(f"--seeds {seeds}: give between 1 and {MAX_SEEDS:,} seeds (seeds 0..N-1).")
        return list(range(seeds))
    if not seeds or any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
        raise MotorlabError("seeds must be distinct non-negative integers.")
    return list(seeds)


def plan(target: Target, seeds: int | list[int], grid: dict[str, list[Any]], sweep_dir: Path,
         threads: dict[str, str] | None = None) -> tuple[list[dict[str, Any]], tuple[str, ...]]:
    """The sweep's trials, every one checked before any runs, and the target's own --track (its trials
    are tracked there too).

    Raises:
        MotorlabError: an option or recipe field the target does not have, a value its settings refuse.
    """
    combos = settings(grid)
    seed_list = _seeds(seeds)
    if isinstance(target, RecipeTarget):
        return recipe_trials(target, combos, seed_list, sweep_dir, threads or {}), ()
    return command_trials(target, combos, seed_list, sweep_dir, threads or {}), target.track


def run_sweep(target: Target, seeds: int | list[int] = 5, grid: dict[str, list[Any]] | None = None,
              backend: str = "local", address: str | None = None, max_parallel: int | None = None,
              out: Path | None = None, console: Console | None = None) -> dict[str, Any]:
    """Run every seed of every setting of `target` (a step kind's or a recipe's, `motorlab.sweeps.targets`)
    over `grid` ({key: [values]}) and aggregate final return, success rate and steps-to-success across
    seeds with rliable.

    Returns:
        The summary (also `<sweep>/summary.json`), plus "sweep_dir".

    Raises:
        MotorlabError: bad settings (before anything runs); trials that failed (after the
            others finished and the summary of those that did was written).
    """
    console = console or Console(stderr=True)
    launcher.check_execution(backend, address, max_parallel)
    parallel = max_parallel or ((os.cpu_count() or 1) if backend == "local" else None)
    # Several trials per machine: one math thread each, or they fight over the cores.
    threads = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"} if parallel != 1 else {}
    sweep_dir = run_path(out, "sweep")
    refuse_finished(sweep_dir, resumable=True, kind="sweep")  # a finished sweep is continued (--resume) or replaced, never by accident
    trials, track = plan(target, seeds, grid or {}, sweep_dir, threads)
    with trackers.also(track, "the sweep's target"):  # checked before anything is written
        return _run(target, trials, grid or {}, backend, address, max_parallel, parallel, sweep_dir, console)


def _run(target: Target, trials: list[dict[str, Any]], grid: dict[str, list[Any]], backend: str, address: str | None,
         max_parallel: int | None, parallel: int | None, sweep_dir: Path, console: Console) -> dict[str, Any]:
    """The planned trials run (those not finished yet), then aggregated."""
    labels = list(dict.fromkeys(t["setting"] for t in trials))
    config = mask_secrets({"sweep": target.text, "seeds": sorted({t["seed"] for t in trials}), "grid": grid,
                           "settings": labels, "backend": backend, "address": address, "max_parallel": max_parallel})
    prepare_run_dir(sweep_dir, "sweep", resumable=True)  # unfinished until the aggregate is written (--overwrite: a fresh folder)
    write_config(sweep_dir, config)
    todo = [t for t in trials if not is_finished(t)]
    kept = len(trials) - len(todo)
    console.print(f"sweep: {len(trials)} trials ({len(labels)} setting{'s' * (len(labels) > 1)} × "
                  f"{len(trials) // len(labels)} seeds)" + (f", {kept} already finished, kept" if kept else "")
                  + (f"; running {len(todo)} on {backend}" + (f" ({parallel} at a time)" if parallel else "")
                     if todo else ""))
    # --track: the sweep is a parent run; each trial's run (its own process) nests under it
    with trackers.parent("sweep", sweep_dir, config):
        for t in todo:
            t["job"] = jobs.tracked(t["job"]).as_dict()  # Ray workers on other machines get it too
        t0 = time.perf_counter()
        if todo:
            with Progress(TextColumn("[bold]sweep[/bold]"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                          console=console, transient=True) as bar:
                task = bar.add_task("trials", total=len(todo))

                def on_done(t: dict[str, Any], rc: int, seconds: float) -> None:
                    bar.advance(task)
                    if rc == 0:
                        scores = trial_scores(read_json(Path(t["run_dir"]) / "summary.json"))
                        ret = scores.get("final_return")
                        shown = f": final return {ret[0]:,.1f}" if ret else ""
                        console.print(f"  [green]✓[/green] {t['name']}{shown} ({seconds:.0f} s)")
                    else:
                        console.print(f"  [red]✗[/red] {t['name']} failed (exit {rc}): "
                                      f"{launcher.last_line(t['log'])}")

                try:
                    if backend == "local":
                        launcher.run_local(todo, parallel, on_done)
                    else:
                        launcher.run_ray(todo, address, max_parallel, 1, sweep_dir / "ray", on_done)
                except KeyboardInterrupt:
                    console.print("sweep interrupted: finished trials are kept; run the same command again to resume.")
                    raise
        done = [t for t in trials if is_finished(t)]
        failed = [t for t in trials if not is_finished(t)]  # also those a Ray worker lost without reporting
        summary = _write_results(target, trials, done, sweep_dir, time.perf_counter() - t0, console)
        trackers.outputs(sweep_dir, summary)  # summary.json, table.txt, plots, report.html
        if failed:
            names = ", ".join(t["name"] for t in failed)
            raise MotorlabError(f"{len(failed)} of {len(trials)} trials failed ({names}); "
                                f"see {Path(failed[0]['log'])}. Fix the cause and run the same command again: "
                                "finished trials are kept.")
    return summary


def _write_results(target: Target, trials: list[dict[str, Any]], done: list[dict[str, Any]], sweep_dir: Path,
                   wall: float, console: Console) -> dict[str, Any]:
    labels = list(dict.fromkeys(t["setting"] for t in trials))
    scores = {s: [trial_scores(read_json(Path(t["run_dir"]) / "summary.json")) for t in done if t["setting"] == s]
              for s in labels}
    scores = {s: v for s, v in scores.items() if v}
    flat, details = aggregate(scores) if scores else ({}, {"metrics": {}, "probability_of_improvement": {},
                                                            "profiles": {}})
    text = target.text  # the sweep's files, plots and report record it, credentials masked
    summary = {"sweep": text, "description": f"{len(labels)} settings × {len(trials) // max(1, len(labels))} "
               "seeds; IQM from 4 seeds (else the mean), 95% stratified-bootstrap CIs from 5 (rliable), the seeds' range below",
               "steps": labels, "trials": len(trials),
               "finished": len(done), "failed": len(trials) - len(done), "wall_seconds": round(wall, 2), **flat}
    write_json(sweep_dir / "aggregate.json", {"runs": {s: [t["run_dir"] for t in done if t["setting"] == s]
                                                       for s in labels}, **details})
    title = f"sweep of {target.path.name if isinstance(target, RecipeTarget) else text}"
    title = title if len(title) <= 60 else title[:57] + "..."
    if details["metrics"]:
        sweep_plots.interval_estimates(details["metrics"], sweep_dir / "plots" / "iqm.png", title)
    if details["probability_of_improvement"]:
        sweep_plots.improvement(details["probability_of_improvement"], sweep_dir / "plots" / "improvement.png", title)
    if details["profiles"]:
        sweep_plots.performance_profiles(details["profiles"], sweep_dir / "plots" / "profiles.png", title)
    rows = _rows(details["metrics"])
    atomic_write_text(sweep_dir / "table.txt", plain_table(COLUMNS, mask_secrets(rows)))
    write_summary(sweep_dir, summary)
    console.print(rich_table(f"{title}: across seeds", COLUMNS, rows, left=("setting", "metric", "per seed")))
    build_report([sweep_dir], sweep_dir / "report.html")
    summary["sweep_dir"] = str(sweep_dir)
    return summary


COLUMNS = ["setting", "metric", "seeds", "over seeds", "interval", "mean", "per seed"]


def _rows(metrics: dict[str, dict[str, Any]]) -> list[list[str]]:
    def f(v: float, metric: str) -> str:
        if metric.endswith("success_rate"):
            return f"{v:.0%}"
        return f"{v:,.0f}" if metric.endswith("steps_to_success") else f"{v:,.1f}"

    rows = []
    for metric, per_setting in metrics.items():
        for s, e in per_setting.items():
            seeds = str(len(e["values"])) + (f" ({e['unsolved']} unsolved)" if e.get("unsolved") else "")
            per_seed = " ".join(f(v, metric) + (" (censored)" if c else "")
                                for v, c in zip(e["values"], e.get("censored", [False] * len(e["values"]))))
            if "statistic" not in e:  # steps to success: k of n, the censored median; no mean of budgets
                rows.append([s, metric, seeds, e["text"], "", "", per_seed])
                continue
            ci = f"[{f(e['ci'][0], metric)}, {f(e['ci'][1], metric)}]" if e["ci"] else e["method"]
            rows.append([s, metric, seeds, f"{e['statistic']} {f(e['value'], metric)}", ci, f(e["mean"], metric),
                         per_seed])
    return rows
