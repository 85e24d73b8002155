"""`motorlab run RECIPE`: each step writes its own run folder inside the study folder.

    <study>/<step>/            one folder per step (steps run for several seeds: <step>/seed<k>/)
    <study>/table.txt          the printed table: each step's numbers, labelled, in their units
    <study>/results.json       the findings (the numbers the recipe is about, with seeds and
                               intervals) and each step's numbers as shown (motorlab.report.results)
    <study>/summary.json       "<step>.<key>" headline numbers, for programs
    <study>/plots/*.png        returns and steps-to-success of the steps that have them
    <study>/report.html        all of it in one self-contained page (motorlab report)

Re-running a study into the same folder keeps steps that finished with the same
settings, so an interrupted study resumes where it stopped (a train step from its last
checkpoint). A finished study is run again only with --resume (keep the steps that finished
with the same settings; a step whose settings or inputs changed is replaced whole, its old
folder deleted only once the study finishes) or --overwrite (replace the study whole);
without either, a step that finished with other settings is refused, never overwritten.
Every folder a study writes is checked to lie inside it. The runner knows no step kind
by name: each step's kind (motorlab.stepkind) says how it runs and what the table shows.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import threading
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape

from motorlab import jobs, launcher, trackers
from motorlab.errors import MotorlabError
from motorlab.intervals import PooledRate, across_seeds, pooled_rate
from motorlab.launcher import trial
from motorlab.recipes import FindingSpec, Recipe, Step, refs_in
from motorlab.report.html import build_report
from motorlab.report.plots import comparison_bars
from motorlab.report.results import (
    DEMO_LABEL,
    Finding,
    StepResults,
    StudyResults,
    results_text,
    write_run_results,
    write_study_results,
)
from motorlab.report.tables import plain_table, rich_table
from motorlab.runs import (
    STUDY,
    atomic_write_bytes,
    atomic_write_text,
    claim_folder,
    finished_with,
    folder_mode,
    inside,
    is_complete,
    move_aside,
    prepare_run_dir,
    read_json,
    replacements,
    toml_holds,
    write_config,
    write_summary,
    write_toml,
    wrote_into,
)
from motorlab.settings import Settings, Summary
from motorlab.stats import steps_to_success
from motorlab.studies.schedule import Overlaps, run_overlapped

STEP_FILE = "recipe_step.toml"  # what the study asked of a step, for resuming
COLUMNS = ["step", "what", "results", "setup", "notes"]


@dataclass(frozen=True)
class _Outcome:
    """What one step gave: its headline (several seeds: aggregated) and each run's summary,
    labelled by its folder ("seed1") where the step has several."""

    headline: dict[str, Any]
    runs: list[tuple[str, Summary]]


@dataclass(frozen=True)
class Execution:
    """Where the seeds of a multi-seed training step run: `local` (processes on this machine, at
    most `max_parallel` at once; default cores // n_envs) or `ray` (Ray Tune, see motorlab.sweeps)."""

    backend: str = "local"
    address: str | None = None
    max_parallel: int | None = None
    parallel_steps: int | None = None  # training steps run at once (default: the recipe's parallel_steps)


class _Outputs:
    """Run folders each finished step produced, for "@step" references."""

    def __init__(self, steps: list[Step]):
        self.kinds = {s.name: s.kind for s in steps}
        self.dirs: dict[str, list[Path]] = {}
        self.ran: set[str] = set()  # steps that ran to their end (not kept) in this invocation
        # what may replace a step that finished with other settings (captured here: steps may run in
        # threads, which do not inherit the run_folders block)
        self.mode = folder_mode()
        self.replaced = replacements()

    def paths(self, name: str) -> list[str]:
        """What "@name" stands for: each of its run folders, or the file in it that its kind provides."""
        artifact = self.kinds[name].provides
        file = artifact.file if artifact is not None else None
        return [str(d / file) if file else str(d) for d in self.dirs[name]]

    def resolve(self, value: Any, each: int | None = None) -> Any:
        """`value` with "@step" references replaced by paths: in a list, every seed's; in a single
        value, seed `each`'s (the first when None)."""
        if isinstance(value, str) and value.startswith("@"):
            paths = self.paths(value[1:])
            return paths[each] if each is not None and len(paths) > 1 else paths[0]
        if isinstance(value, list):
            return [p for v in value for p in (self.paths(v[1:]) if isinstance(v, str) and v.startswith("@")
                                               else [v])]
        if isinstance(value, dict):
            return {k: self.resolve(v) for k, v in value.items()}
        return value


def _fan_out(step: Step, outputs: _Outputs) -> str | None:
    """The single-valued reference to a step run for several seeds, where this step runs once per seed."""
    if not step.kind.per_seed:
        return None
    return next((name for ref in step.kind.refs for name in refs_in(step.fields.get(ref.field))
                 if isinstance(step.fields.get(ref.field), str) and len(outputs.dirs[name]) > 1), None)


def _run_dirs(step: Step, study_dir: Path) -> list[Path]:
    """A step's run folders by its own seeds: <step>/, or <step>/seed<k>/ for each of several."""
    dirs = [study_dir / step.name / f"seed{s}" for s in step.seeds] if step.seeds else [study_dir / step.name]
    return [inside(study_dir, d, f"step {step.name!r}") for d in dirs]


def _runs(step: Step, study_dir: Path, outputs: _Outputs) -> list[tuple[Path, Settings]]:
    """The run folders of a step and the settings each runs with, references resolved."""
    k = step.kind
    is_ref = {r.field for r in k.refs}
    fields = {f: outputs.resolve(v) if f in is_ref else v for f, v in step.fields.items()}
    if step.seeds:
        settings = k.validate(fields)
        return [(d, step.kind.seeded(settings, s)) for d, s in zip(_run_dirs(step, study_dir), step.seeds)]
    fan = _fan_out(step, outputs)
    if fan is None:
        return [(_run_dirs(step, study_dir)[0], k.validate(fields))]
    runs = []
    for i, d in enumerate(outputs.dirs[fan]):  # one run per seed of the step it names
        each = {f: outputs.resolve(step.fields[f], i) if f in is_ref else v for f, v in fields.items()}
        runs.append((inside(study_dir, study_dir / step.name / d.name, f"step {step.name!r}"), k.validate(each)))
    return runs


def _upstream(step: Step, outputs: _Outputs) -> dict[str, str]:
    """A fingerprint of every run folder this step reads ("@step" references): the hash of
    its summary.json, which is rewritten whenever that step runs again. A step whose
    inputs were redone is redone too, even when its own settings did not change."""
    dirs = [d for name in step.inputs() for d in outputs.dirs[name]]
    return {str(d): hashlib.sha256((d / "summary.json").read_bytes()).hexdigest()[:16] for d in dirs}


def _run_step(step: Step, study_dir: Path, outputs: _Outputs, console: Console, execution: Execution,
              detached: bool = False, stop: threading.Event | None = None) -> _Outcome:
    """Run one step (or keep its finished runs); returns what it gave.

    Args:
        detached: a training step runs as its own process even with one seed (it runs beside
            other steps; see studies/schedule.py), and stops when `stop` is set.
    """
    k = step.kind
    upstream = _upstream(step, outputs)
    runs = _runs(step, study_dir, outputs)
    asked = {d: {"settings": settings.config(), "upstream": upstream} for d, settings in runs}
    kept = [d for d, _ in runs if finished_with(d, asked[d], STEP_FILE)]
    for d in kept:
        console.print(f"      {f'{d.name}: ' if len(runs) > 1 else ''}already done with these settings; kept")
    todo = [(d, settings) for d, settings in runs if d not in kept]
    changed = [d for d, _ in todo if is_complete(d)]  # finished, but with other settings or inputs
    if changed and (outputs.mode != "resume" or outputs.replaced is None):
        raise MotorlabError(f"step {step.name}: {changed[0]} finished with other settings; give --resume to redo "
                            "the changed steps (keeping the others), --overwrite to redo the whole study, or "
                            "another --out.")
    for d in changed:  # --resume: replaced whole, the old run put back if the study does not finish
        move_aside(d, outputs.replaced)
        console.print(f"      {f'{d.name}: ' if len(runs) > 1 else ''}settings or inputs changed; its earlier run "
                      "is replaced")
    # an interrupted run of these very settings continues from its checkpoint, as `train --resume` does
    resuming = {d for d, _ in todo if toml_holds(d / STEP_FILE, asked[d]) and k.can_resume(d)}
    for d, _ in todo:
        # What the study asks is written first, and any older summary removed: a summary.json
        # from now on is this run's, even when Ctrl-C lands between it and the run's exit. The
        # folder is marked as the step's kind first (its run, here or in a worker, locks it).
        claim_folder(d, k.name)
        (d / "summary.json").unlink(missing_ok=True)
        write_toml(d / STEP_FILE, asked[d])
    if k.trains and (detached or len(runs) > 1) and todo:
        _run_processes(step, todo, execution, console, stop)
    else:
        for d, settings in todo:
            if d in resuming:
                console.print("      continuing the interrupted run from its last checkpoint")
                k.perform(settings, d, resume=True, console=console)  # under the study's run-folder mode
            else:
                k.perform(settings, d, console=console)
    if todo:
        outputs.ran.add(step.name)
    if not detached:  # matplotlib is not thread-safe: a background step's figures are drawn by the study's thread
        for d, _ in runs:
            k.figures(d)
            wrote_into(d)
    outputs.dirs[step.name] = [d for d, _ in runs]
    summaries = [k.summary.model_validate(read_json(d / "summary.json")) for d, _ in runs]
    for (d, settings), summary in zip(runs, summaries):
        if d in kept:  # runs made now wrote theirs; kept ones get their numbers as this version shows them
            write_run_results(d, k.results(settings, summary))
            wrote_into(d)
    labels = [d.name if len(runs) > 1 else step.name for d, _ in runs]
    return _Outcome(k.aggregate(summaries), list(zip(labels, summaries)))


def _run_processes(step: Step, todo: list[tuple[Path, Settings]], execution: Execution, console: Console,
                   stop: threading.Event | None = None) -> None:
    """Train several seeds at once (or one seed beside other steps) as sweep trials: each a
    motorlab.worker process whose job (kind and settings) is <step>/logs/seed<k>.job.json
    (<study>/logs/<step>.job.json for a step with one seed), beside its log."""
    k = step.kind
    n_envs = getattr(todo[0][1], "n_envs", 1)
    parallel = execution.max_parallel or max(1, (os.cpu_count() or 1) // n_envs)
    threads = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}  # one math thread per seed process
    trials = []
    for run_dir, settings in todo:
        logs = run_dir.parent / "logs"
        job = jobs.tracked(jobs.job(k.name, settings.config(), {"out": run_dir.resolve()}))
        trials.append(trial(f"{step.name}/{run_dir.name}", step.name, getattr(settings, step.kind.SEED, 0), job, run_dir,
                            logs / f"{run_dir.name}.log", threads))
    where = execution.backend + (f" at {execution.address}" if execution.address else "")
    if len(trials) == 1:
        console.print(f"      {step.name}: one process, log {trials[0]['log']}")
    else:
        console.print(f"      {len(trials)} seeds in parallel ({where}"
                      + (f", {parallel} at a time)" if execution.backend == "local" else ")"))

    def on_done(t: dict[str, Any], rc: int, seconds: float) -> None:
        name = Path(t["run_dir"]).name
        if rc == 0 and len(trials) == 1:
            return  # one seed beside other steps: the study says when the step is done
        if rc == 0:
            scores = k.scores(k.summary.model_validate(read_json(Path(t["run_dir"]) / "summary.json")))
            console.print(f"      {name}: return {scores.return_mean:,.1f} ({seconds:.0f} s)")
        else:
            console.print(f"      {name}: failed (exit {rc}), log {t['log']}")

    if execution.backend == "ray":
        launcher.run_ray(trials, execution.address, execution.max_parallel, n_envs,
                         todo[0][0].parent / "ray", on_done)
    else:
        launcher.run_local(trials, parallel, on_done, stop)
    failed = [t for t in trials if not is_complete(Path(t["run_dir"]))]
    if failed:
        raise MotorlabError(f"step {step.name}: {', '.join(Path(t['run_dir']).name for t in failed)} failed: "
                            f"{launcher.last_line(failed[0]['log'])}.")


def describe(step: Step) -> str:
    """The "what" column of a step."""
    return step.kind.describe(step.settings, copies=len(step.seeds or []))


def run_study(recipe: Recipe, out: Path | None = None, console: Console | None = None,
              execution: Execution | None = None) -> dict[str, Any]:
    """Run every step of `recipe`, write the study's table, plots and summary.json.

    Args:
        execution: where the seeds of a training step with several seeds run (default: in
            parallel on this machine, one process per seed).

    Returns:
        The study summary (flat keys "<step>.<key>", plus "study_dir").
    """
    console = console or Console(stderr=True)
    execution = execution or Execution()
    launcher.check_execution(execution.backend, execution.address, execution.max_parallel)
    if execution.parallel_steps is not None and execution.parallel_steps < 1:
        raise MotorlabError(f"--parallel-steps {execution.parallel_steps}: give at least 1.")
    parallel_steps = execution.parallel_steps or recipe.parallel_steps
    if parallel_steps > 1 and execution.backend != "local":
        if execution.parallel_steps:
            raise MotorlabError(f"--parallel-steps {parallel_steps} runs steps as processes on this machine; with "
                                f"--backend {execution.backend} give --parallel-steps 1 (the cluster runs each "
                                "step's seeds at once).")
        console.print(f"      the recipe's parallel_steps = {parallel_steps} applies on this machine only; with "
                      f"--backend {execution.backend} its steps run one after another")
        parallel_steps = 1
    finished = {f: (Path(out) / f).read_bytes() for f in ("summary.json", "config.toml")} \
        if out is not None and is_complete(Path(out)) else {}
    study_dir = prepare_run_dir(out, recipe.name, resumable=True, kind=STUDY)  # a finished study needs --resume
    config = {"recipe": recipe.name, "source": recipe.source, "steps": [s.name for s in recipe.steps]}
    write_config(study_dir, config)
    outputs = _Outputs(recipe.steps)
    try:
        # --track: the study is a parent run; each step's run (here, or in its own process) nests under it
        with trackers.parent("study", study_dir, config):
            summary = _run_steps(recipe, study_dir, console, execution, parallel_steps, outputs)
            trackers.outputs(study_dir, summary)  # summary.json, results.json, table.txt, plots, report.html
    except BaseException:
        if finished and not outputs.ran:  # --resume of a finished study stopped before any step ran: still finished
            for name, data in finished.items():
                atomic_write_bytes(study_dir / name, data)
        raise
    return summary


def _run_steps(recipe: Recipe, study_dir: Path, console: Console, execution: Execution,
               parallel_steps: int, outputs: _Outputs) -> dict[str, Any]:
    """The study's steps, then its table, findings, figures, summary.json and report (see run_study)."""
    t0 = time.perf_counter()
    overlaps = Overlaps()
    seconds: dict[str, float] = {}  # each step's wall time (beside others, where steps overlap)

    def timed(step: Step, *args: Any) -> _Outcome:
        t_step = time.perf_counter()
        try:
            return _run_step(step, study_dir, outputs, console, execution, *args)
        finally:
            seconds[step.name] = round(time.perf_counter() - t_step, 1)

    if parallel_steps > 1:
        console.print(f"      training steps that need nothing from each other run at once, at most {parallel_steps}")
        for kind in {s.kind.name: s.kind for s in recipe.steps}.values():
            kind.warm_up()  # before any thread starts: threads must not import a package at the same time
        results, overlaps = run_overlapped(
            recipe.steps, timed,
            parallel_steps, console, lambda step: _progress(step, study_dir), describe,
            lambda step: [step.kind.figures(d) for d in outputs.dirs[step.name]])
    else:
        results = {}
        for i, step in enumerate(recipe.steps, 1):
            console.print(f"[bold][{i}/{len(recipe.steps)}][/bold] {step.name}: {describe(step)}")
            results[step.name] = timed(step)
            console.print(f"      done in {seconds[step.name]:.1f} s")
    study_summary: dict[str, Any] = {"recipe": recipe.name, "description": recipe.description,
                                     "steps": [s.name for s in recipe.steps],
                                     "parallel_steps": parallel_steps,
                                     "wall_seconds": round(time.perf_counter() - t0, 2), "step_seconds": seconds}
    for name in (s.name for s in recipe.steps):
        study_summary.update({f"{name}.{k}": v for k, v in results[name].headline.items()})
    _figures(recipe, {name: r.headline for name, r in results.items()}, study_dir)
    steps = [_step_results(s, results[s.name].headline, sorted(overlaps.beside.get(s.name, ())),
                           outputs.dirs[s.name], study_dir) for s in recipe.steps]
    rows = [[r.step, r.what, results_text(r.numbers), results_text(r.numbers, setup=True), r.note] for r in steps]
    atomic_write_text(study_dir / "table.txt", plain_table(COLUMNS, rows))
    write_study_results(study_dir, StudyResults(_findings(recipe, results, console), steps, recipe.demo))
    write_summary(study_dir, study_summary)
    console.print(rich_table(f"{recipe.name}: {recipe.description}" if recipe.description else recipe.name,
                             COLUMNS, rows, left=tuple(COLUMNS)))
    if recipe.demo:  # its small budgets or seeds are on purpose: said wherever its numbers are shown
        console.print(f"[bold yellow]{DEMO_LABEL}:[/bold yellow] {escape(recipe.demo)}")
    build_report([study_dir], study_dir / "report.html")
    study_summary["study_dir"] = str(study_dir)
    return study_summary


def _progress(step: Step, study_dir: Path) -> tuple[int, int]:
    """Work a background step has done so far (all its seeds), and its total."""
    done = [step.kind.progress(step.settings, d) for d in _run_dirs(step, study_dir)]
    return sum(d for d, _ in done), sum(t for _, t in done)


def _step_results(step: Step, headline: dict[str, Any], beside: list[str], run_dirs: list[Path],
                  study_dir: Path) -> StepResults:
    k = step.kind
    note = k.notes(step.settings, headline)
    if beside:  # its wall time was shared with these steps
        note = "; ".join(x for x in (note, f"ran beside {', '.join(beside)}") if x)
    figures = [(d / f).relative_to(study_dir).as_posix() for d in run_dirs[:1] for f in k.key_figures
               if (d / f).is_file()]  # several seeds: the first one's (the report has every seed's below)
    return StepResults(step.name, k.name, describe(step), k.numbers(step.settings, headline), note, figures)


def _findings(recipe: Recipe, results: dict[str, _Outcome], console: Console) -> list[Finding]:
    """The numbers the recipe is about (its [[findings]], else each step's own), each with its
    seeds and, where there are several, what they give together (motorlab.intervals): rliable's IQM
    from 4 seeds, its 95% bootstrap CI from 5, the seeds' range (named so) below."""
    by_name = {s.name: s for s in recipe.steps}
    specs = recipe.findings or [FindingSpec(step=s.name, key=key) for s in recipe.steps
                                for key in s.kind.default_findings(s.settings, results[s.name].headline)]
    findings = []
    for spec in specs:
        step, outcome = by_name[spec.step], results[spec.step]
        if spec.key not in outcome.headline:
            console.print(f"[yellow]finding {spec.step}.{spec.key}: {spec.step} has no number {spec.key!r}; it has "
                          f"{', '.join(outcome.headline)}[/yellow]")
            continue
        metric = step.kind.metric(spec.key)
        value = outcome.headline[spec.key]
        per_seed = step.kind.seed_values(outcome.runs, spec.key)
        label = spec.label or f"{spec.step}: {metric.label}"
        finding = Finding(label, spec.step, spec.key, metric.text(value, outcome.headline) if value is not None
                          else "not reached", value)
        if len(per_seed) > 1:
            seeds, values = [s for s, _ in per_seed], [v for _, v in per_seed]
            shown = [metric.text(v, {}) if v is not None else "not reached" for v in values]
            together: dict[str, Any] = {}
            if spec.key == "steps_to_success":
                together = _censored_steps(step, outcome)
            elif all(isinstance(v, (int, float)) for v in values):
                summary = across_seeds(values)  # the IQM from 4 seeds; a CI from 5, the seeds' range below
                interval = summary.interval
                together = {"aggregate": f"{summary.statistic} {metric.text(summary.value, {})}",
                            "ci": metric.interval(*interval) if interval else None, "ci_method": summary.method}
            finding = dataclasses.replace(finding, seeds=seeds, values=shown, **together)
        if pooled := _pooled_success(step, outcome, spec.key):
            finding = dataclasses.replace(finding, pooled=pooled.text(partial(metric.text, values={})))
        findings.append(finding)
    return findings


def _censored_steps(step: Step, outcome: _Outcome) -> dict[str, Any]:
    """Steps to success over seeds: "k of n seeds" with its Wilson interval and the Kaplan-Meier
    median with its bootstrap interval from 5 seeds (each named in the text), a seed that never
    solved censored at the steps it was allowed (its run's timesteps), never counted as a value."""
    heads = [step.kind.headline(s) for _, s in outcome.runs]
    steps = [h.get("steps_to_success") for h in heads]
    budgets = [step.kind.budget(h) for h in heads]
    if any(b is None for b in budgets):
        return {}
    reached = steps_to_success(steps, budgets)
    return {"aggregate": reached.text, "ci": None, "ci_method": "unsolved seeds censored at their budgets"}


def _pooled_success(step: Step, outcome: _Outcome, key: str) -> PooledRate | None:
    """A success rate's episodes pooled over the step's runs, with their Wilson interval: where
    each run's headline says how many episodes its rate is of (None otherwise)."""
    if key != "success_rate":
        return None
    counts = [(h.get("success_rate"), h.get("episodes")) for h in (step.kind.headline(s) for _, s in outcome.runs)]
    if not counts or not all(isinstance(r, (int, float)) and isinstance(n, int) and n > 0 for r, n in counts):
        return None
    successes = [round(r * n) for r, n in counts]
    if any(abs(k - r * n) > 1e-6 * n for k, (r, n) in zip(successes, counts)):
        return None  # not a share of whole episodes (e.g. a rate averaged some other way)
    return pooled_rate(successes, [n for _, n in counts])


def _figures(recipe: Recipe, results: dict[str, dict[str, Any]], study_dir: Path) -> None:
    """The study's charts, each only where it has something to show: a bar chart whose bars
    are all missing says nothing (e.g. steps to success where no step aims to solve)."""
    scored = [s.name for s in recipe.steps if s.kind.scored]
    comparison_bars(scored, [results[n].get("return_mean") for n in scored], "evaluation return (mean)",
                    study_dir / "plots" / "returns.png", f"{recipe.name}: return of each step",
                    caption="Mean evaluation return of each step that trains or evaluates a policy "
                            "(several seeds: the mean over seeds).")
    solving = [s.name for s in recipe.steps if s.kind.trains and s.kind.stops_early(s.settings)]
    # several seeds: the bar is their Kaplan-Meier median (unsolved seeds censored at their budgets),
    # labelled with how many solved; no bar where fewer than half did (the median is above the budget)
    notes = [f"{results[n]['steps_to_success_solved']} of {results[n]['seeds']} seeds solved"
             if "steps_to_success_solved" in results[n] and "seeds" in results[n] else None for n in solving]
    comparison_bars(solving, [results[n].get("steps_to_success") for n in solving], "environment steps",
                    study_dir / "plots" / "steps_to_success.png", f"{recipe.name}: steps until consistently solved",
                    steps=True, missing_label="not within the budget", notes=notes,
                    caption="Environment steps each training needed until its evaluations were consistently "
                            "solved; with several seeds the Kaplan-Meier median, unsolved seeds censored at their "
                            "budgets (grey: not within the budget, or fewer than half the seeds solved).")
