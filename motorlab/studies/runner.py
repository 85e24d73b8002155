"""`motorlab run RECIPE`: each step writes its own run folder inside the study folder.

    <study>/<step>/            one folder per step (train steps with several seeds: <step>/seed<k>/)
    <study>/table.txt          the printed table
    <study>/summary.json       "<step>.<key>" headline numbers
    <study>/plots/*.png        returns and steps-to-success of every step
    <study>/report.html        all of it in one self-contained page (motorlab report)

Re-running a study into the same folder keeps steps that finished with the same
settings, so an interrupted study resumes where it stopped.
"""

from __future__ import annotations

import os
import statistics
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console

from motorlab.errors import MotorlabError
from motorlab.recipes import Recipe, Step
from motorlab.report.html import build_report
from motorlab.report.plots import comparison_bars
from motorlab.report.run import plot_run
from motorlab.report.tables import plain_table, rich_table
from motorlab.studies.schedule import Overlaps, run_overlapped, step_inputs
from motorlab.runs import (atomic_write_text, finished_with, last_timesteps, prepare_run_dir, read_json, write_config,
                           write_summary, write_toml)

STEP_FILE = "recipe_step.toml"  # what the study asked of a step, for resuming
HEADLINE = ("return_mean", "return_std", "return_min", "success_rate", "steps_to_success", "timesteps", "wall_seconds",
            "episode_length_mean", "falls", "episodes")


@dataclass(frozen=True)
class Execution:
    """Where the seeds of a multi-seed train step run: `local` (processes on this machine, at
    most `max_parallel` at once; default cores // n_envs) or `ray` (Ray Tune, see motorlab.sweeps)."""

    backend: str = "local"
    address: str | None = None
    max_parallel: int | None = None
    parallel_steps: int | None = None  # train steps run at once (default: the recipe's parallel_steps)


class _Outputs:
    """Run folders each finished step produced, for "@step" references."""

    def __init__(self, study_dir: Path):
        self.study_dir = study_dir
        self.dirs: dict[str, list[Path]] = {}

    def one(self, ref: str) -> Path:
        return self.dirs[ref[1:]][0] if ref.startswith("@") else Path(ref)

    def many(self, refs: list[str]) -> list[tuple[str, Path]]:
        """(label, run folder) for each referenced run, all seeds of a train step."""
        out = []
        for ref in refs:
            if not ref.startswith("@"):
                out.append((Path(ref).name, Path(ref)))
                continue
            dirs = self.dirs[ref[1:]]
            out += [(ref[1:] if len(dirs) == 1 else f"{ref[1:]}/{d.name}", d) for d in dirs]
        return out


def _train_configs(step: Step, study_dir: Path, outputs: _Outputs) -> list[tuple[Path, Any]]:
    cfg = step.train
    if step.sar_ref:
        cfg = cfg.model_copy(update={"env": cfg.env.model_copy(
            update={"sar": str((outputs.one(step.sar_ref) / "sar.npz").resolve())})})
    if not step.seeds:
        return [(study_dir / step.name, cfg)]
    return [(d, cfg.model_copy(update={"seed": s})) for d, s in zip(_run_dirs(step, study_dir), step.seeds)]


def _run_dirs(step: Step, study_dir: Path) -> list[Path]:
    """A train step's run folders: <step>/, or <step>/seed<k>/ for each of several seeds."""
    return [study_dir / step.name / f"seed{s}" for s in step.seeds] if step.seeds else [study_dir / step.name]


def _upstream(step: Step, outputs: _Outputs) -> dict[str, str]:
    """A fingerprint of every run folder this step reads ("@step" references): the hash of
    its summary.json, which is rewritten whenever that step runs again. A step whose
    inputs were redone is redone too, even when its own settings did not change."""
    import hashlib

    dirs = [d for name in step_inputs(step) for d in outputs.dirs[name]]
    return {str(d): hashlib.sha256((d / "summary.json").read_bytes()).hexdigest()[:16] for d in dirs}


def _run_step(step: Step, study_dir: Path, outputs: _Outputs, console: Console, execution: Execution,
              detached: bool = False, stop: threading.Event | None = None) -> dict[str, Any]:
    """Run one step (or keep its finished result); returns its headline numbers.

    Args:
        detached: a train step runs as its own process even with one seed (it runs beside
            other steps; see studies/schedule.py), and stops when `stop` is set.
    """
    from motorlab.rl.train import train

    step_dir = study_dir / step.name
    upstream = _upstream(step, outputs)
    if step.kind == "train":
        runs = _train_configs(step, study_dir, outputs)
        asked = {d: {"train": cfg.model_dump(), "upstream": upstream} for d, cfg in runs}
        kept = [d for d, _ in runs if finished_with(d, asked[d], STEP_FILE)]
        for d in kept:
            console.print(f"      {d.name}: already done with these settings; kept")
        todo = [(d, cfg) for d, cfg in runs if d not in kept]
        for d, _ in todo:
            # What the study asks is written first, and any older summary removed: a summary.json
            # from now on is this training's, even when Ctrl-C lands between it and the run's exit.
            (d / "summary.json").unlink(missing_ok=True)
            write_toml(d / STEP_FILE, asked[d])
        if len(todo) == 1 and len(runs) == 1 and not detached:
            train(todo[0][1], todo[0][0])  # one run: in this process, with its progress bar
        elif todo:
            _train_seeds(step, todo, execution, console, stop)
        if not detached:  # matplotlib is not thread-safe: a background step's figures are drawn by the study's thread
            for d, _ in runs:
                plot_run(d)
        outputs.dirs[step.name] = [d for d, _ in runs]
        return _seeds_headline([read_json(d / "summary.json") for d, _ in runs], "eval_")
    refs = _policy_runs(step, outputs)
    if len(refs) > 1:  # a policy trained with several seeds: evaluate each one
        return _evaluate_seeds(step, refs, upstream, study_dir, console, outputs)
    config = {**_step_config(step, outputs), "upstream": upstream}
    outputs.dirs[step.name] = [step_dir]
    if finished_with(step_dir, config, STEP_FILE):
        console.print("      already done with these settings; kept")
        summary = read_json(step_dir / "summary.json")
    else:
        summary = _execute(step, config, step_dir, console)
        write_toml(step_dir / STEP_FILE, config)
    if step.kind == "evaluate":
        plot_run(step_dir)
        return _seeds_headline([summary], "")
    return _other_headline(step, summary)


def _train_seeds(step: Step, todo: list[tuple[Path, Any]], execution: Execution, console: Console,
                 stop: threading.Event | None = None) -> None:
    """Train several seeds at once (or one seed beside other steps) as sweep trials: each a
    `motorlab train --config` process whose config the study wrote to <step>/logs/seed<k>.toml
    (<study>/logs/<step>.toml for a step with one seed), beside its log."""
    from motorlab.sweeps import backends
    from motorlab.sweeps.trials import trial

    n_envs = step.train.n_envs
    parallel = execution.max_parallel or max(1, (os.cpu_count() or 1) // n_envs)
    threads = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}  # one math thread per seed process
    trials = []
    for run_dir, cfg in todo:
        logs = run_dir.parent / "logs"
        write_toml(logs / f"{run_dir.name}.toml", cfg.model_dump())
        argv = ["train", "--config", (logs / f"{run_dir.name}.toml").resolve(), "--out", run_dir, "--no-progress"]
        trials.append(trial(f"{step.name}/{run_dir.name}", step.name, cfg.seed, argv, run_dir,
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
            s = read_json(Path(t["run_dir"]) / "summary.json")
            console.print(f"      {name}: return {s['eval_return_mean']:,.1f} ({seconds:.0f} s)")
        else:
            console.print(f"      {name}: failed (exit {rc}), log {t['log']}")

    if execution.backend == "ray":
        backends.run_ray(trials, execution.address, execution.max_parallel, n_envs,
                         todo[0][0].parent / "ray", on_done)
    else:
        backends.run_local(trials, parallel, on_done, stop)
    failed = [t for t in trials if not (Path(t["run_dir"]) / "summary.json").is_file()]
    if failed:
        raise MotorlabError(f"step {step.name}: {', '.join(Path(t['run_dir']).name for t in failed)} failed: "
                            f"{backends.last_line(failed[0]['log'])}.")


def _policy_runs(step: Step, outputs: _Outputs) -> list[Path]:
    """The run folders an evaluate step's "@train-step" policy names (one per seed)."""
    return outputs.dirs[step.policy_ref] if step.kind == "evaluate" and step.policy_ref else []


def _evaluate_seeds(step: Step, refs: list[Path], upstream: dict[str, str], study_dir: Path, console: Console,
                    outputs: _Outputs) -> dict[str, Any]:
    """Evaluate every seed's policy into <step>/seed<k>/; the headline aggregates over seeds."""
    from motorlab.evaluate import evaluate_step

    s = step.settings
    summaries, dirs = [], []
    for ref in refs:
        run_dir = study_dir / step.name / ref.name
        config = {"policy": str(ref), "episodes": s.episodes, "seed": s.seed, "env": s.env.model_dump(),
                  "upstream": upstream}
        if finished_with(run_dir, config, STEP_FILE):
            console.print(f"      {ref.name}: already done with these settings; kept")
            summaries.append(read_json(run_dir / "summary.json"))
        else:
            summaries.append(evaluate_step(str(ref), s.env, s.episodes, s.seed, run_dir))
            write_toml(run_dir / STEP_FILE, config)
        plot_run(run_dir)
        dirs.append(run_dir)
    outputs.dirs[step.name] = dirs
    return _seeds_headline(summaries, "")


def _step_config(step: Step, outputs: _Outputs) -> dict[str, Any]:
    """A non-train step's settings with its references resolved to run folders."""
    s = step.settings
    if step.kind == "evaluate":
        return {"policy": str(outputs.one(s.policy)), "episodes": s.episodes, "seed": s.seed, "env": s.env.model_dump()}
    config = s.model_dump()
    if step.kind in ("collect", "video"):
        config["run"] = str(outputs.one(s.run))
    elif step.kind in ("vaf", "fit"):
        config["activations"] = str(outputs.one(s.activations) / "activations.npz")
    elif step.kind == "zeroshot":
        config["runs"] = {label: str(d) for label, d in outputs.many(s.runs)}
    elif step.kind == "compare":
        config["groups"] = {g: [str(d) for _, d in outputs.many(refs)] for g, refs in s.groups.items()}
    elif step.kind == "dynamics-collect" and s.policy.startswith("@"):
        config["policy"] = str(outputs.one(s.policy))
    elif step.kind == "dynamics-fit":
        config["transitions"] = str(outputs.one(s.transitions) / "transitions.npz")
    elif step.kind in ("dynamics-check", "mpc"):
        config["model"] = str(outputs.one(s.model))
    return config


def _execute(step: Step, c: dict[str, Any], step_dir: Path, console: Console) -> dict[str, Any]:
    if step.kind == "evaluate":
        from motorlab.evaluate import evaluate_step

        return evaluate_step(c["policy"], step.settings.env, c["episodes"], c["seed"], step_dir)
    if step.kind == "video":
        from motorlab.report.video import render_video

        run = prepare_run_dir(step_dir, "video")
        summary = render_video(Path(c["run"]), c["episodes"], c["seed"], out=run)
        write_config(run, c)
        write_summary(run, summary)
        return summary
    if step.kind == "collect":
        from motorlab.synergy.collect import collect

        return collect(Path(c["run"]), c["episodes"], c["percentile"], c["preview"], c["seed"], c["deterministic"],
                       c["workers"], out=step_dir)
    if step.kind == "vaf":
        from motorlab.synergy.steps import vaf_step

        return vaf_step(Path(c["activations"]), c["threshold"], c["method"], c["max_n"], step_dir)
    if step.kind == "fit":
        from motorlab.synergy.steps import fit_step

        return fit_step(Path(c["activations"]), c["n_synergies"], c["vaf"], c["method"], c["seed"], step_dir)
    if step.kind == "zeroshot":
        from motorlab.zeroshot import zeroshot

        return zeroshot([Path(d) for d in c["runs"].values()], c["envs"], c["episodes"], c["seed"], step_dir,
                        console=console, labels=list(c["runs"]))
    if step.kind == "compare":
        from motorlab.report.compare import compare_curves, group_statistics

        run = prepare_run_dir(step_dir, "compare")
        result = compare_curves({g: [Path(d) for d in ds] for g, ds in c["groups"].items()},
                                run / "plots" / "learning_curves.png", c["title"])
        write_config(run, c)
        summary = {f"{label}.{k}": v for label, r in result.items() for k, v in r.items()}
        summary.update(group_statistics(c["groups"]))
        write_summary(run, summary)
        return summary
    if step.kind == "dynamics-collect":
        from motorlab.dynamics.collect import collect_step

        return collect_step(c["env"], c["episodes"], c["policy"], c["workers"], c["seed"], c["state"],
                            c["simulator"], step_dir)
    if step.kind == "dynamics-fit":
        from motorlab.dynamics.train import fit_step

        return fit_step(Path(c["transitions"]), c["epochs"], tuple(c["hidden"]), c["ensemble"], c["lr"],
                        c["batch_size"], c["valid_fraction"], c["patience"], c["seed"], step_dir)
    if step.kind == "dynamics-check":
        from motorlab.dynamics.check import check_step

        return check_step(Path(c["model"]), c["episodes"], c["seed"], c["steps"], step_dir)
    if step.kind == "mpc":
        from motorlab.control.mpc_step import mpc_step

        return mpc_step(c["env"], Path(c["model"]), c["episodes"], c["horizon"], c["population"], c["iterations"],
                        c["elites"], c["optimizer"], c["parallel"], c["seed"], c["video"], step_dir)
    raise AssertionError(step.kind)  # recipes.py admits no other kind


def _seeds_headline(summaries: list[dict[str, Any]], prefix: str) -> dict[str, Any]:
    """Headline of a train (prefix "eval_": its final evaluation) or evaluate step; with several
    seeds, the mean over seeds (std across seeds) and rliable's IQM with its 95% bootstrap CI."""
    if len(summaries) == 1:
        s = summaries[0]
        head = {k: s.get(f"{prefix}{k}", s.get(k)) for k in HEADLINE}
        head["train_success_rate_last100"] = s.get("train_success_rate_last100")
        return {k: v for k, v in head.items() if v is not None or (k == "steps_to_success" and prefix)}
    from motorlab.sweeps.stats import aggregate, trial_scores

    means = [s[f"{prefix}return_mean"] for s in summaries]
    rates = [s.get("train_success_rate_last100") for s in summaries]
    flat, _ = aggregate({"seeds": [trial_scores(s) for s in summaries]})
    head = {
        "seeds": len(summaries),
        "return_mean": statistics.fmean(means),
        "return_std": statistics.stdev(means),
        "return_min": min(s[f"{prefix}return_min"] for s in summaries),
        "return_iqm": flat["seeds.final_return_iqm"],
        "return_iqm_ci_low": flat["seeds.final_return_iqm_ci_low"],
        "return_iqm_ci_high": flat["seeds.final_return_iqm_ci_high"],
        "success_rate": statistics.fmean(s[f"{prefix}success_rate"] for s in summaries),
        "episodes": sum(s.get(f"{prefix}episodes", 0) for s in summaries),
    }
    if prefix:  # training
        solved = [s["steps_to_success"] for s in summaries]
        head.update({
            "train_success_rate_last100": statistics.fmean(rates) if None not in rates else None,
            # a seed that never solved makes the median unknowable, not smaller
            "steps_to_success": statistics.median(solved) if None not in solved else None,
            "timesteps": sum(s["timesteps"] for s in summaries),
            "wall_seconds": sum(s["wall_seconds"] for s in summaries),
        })
    else:
        falls = [s.get("falls") for s in summaries]
        lengths = [s.get("episode_length_mean") for s in summaries]
        if None not in falls:
            head["falls"] = sum(falls)
        if None not in lengths:
            head["episode_length_mean"] = statistics.fmean(lengths)
    return head


def _other_headline(step: Step, s: dict[str, Any]) -> dict[str, Any]:
    if step.kind == "video":
        keys = ("videos", "returns", "fps")
    elif step.kind == "collect":
        keys = ("samples", "n_muscles", "episodes_kept", "threshold", "kept_success_rate")
    elif step.kind == "vaf":
        keys = ("n_for_threshold", "threshold", "n_muscles")
    elif step.kind == "fit":
        keys = ("n_synergies", "n_muscles", "vaf")
    elif step.kind == "zeroshot":
        return {**{k: v for k, v in s.items() if "." in k}, **_zeroshot_means(s)}
    elif step.kind == "dynamics-collect":
        keys = ("transitions", "transitions_per_second", "simulator", "collect_seconds")
    elif step.kind == "dynamics-fit":
        keys = ("valid_mse", "epochs_run", "wall_seconds", "train_rows")
    elif step.kind == "dynamics-check":
        keys = tuple(k for k in s if k.startswith(("tip_error_mean_", "state_nrmse_")))
    elif step.kind == "mpc":
        keys = ("return_mean", "return_std", "return_min", "final_distance_mean", "plan_ms_median", "episodes",
                "wall_seconds")
    else:
        return {k: v for k, v in s.items() if "." in k}  # compare: already "<group>.<key>"
    return {k: s.get(k) for k in keys}


def _zeroshot_means(s: dict[str, Any]) -> dict[str, float]:
    """"<step>.<env>.success_rate_mean": the mean over a train step's seeds."""
    groups: dict[str, list[float]] = {}
    for key, value in s.items():
        if key.endswith(".success_rate") and value is not None:
            label, env_id, _ = key.rsplit(".", 2)
            groups.setdefault(f"{label.split('/')[0]}.{env_id}", []).append(value)
    return {f"{k}.success_rate_mean": statistics.fmean(v) for k, v in groups.items()}


def _describe(step: Step) -> str:
    if step.kind == "train":
        c = step.train
        what = f"{c.preset or c.algo}" + (" until solved" if c.until_solved else f" {c.timesteps:,} steps")
        if step.seeds:
            what += f" × {len(step.seeds)} seeds"
        env = c.env
    elif step.kind == "evaluate":
        what, env = f"evaluate {step.evaluate.policy}", step.evaluate.env
    else:
        s = step.settings
        return {"video": lambda: f"video of {s.run}, {s.episodes} episode{'s' * (s.episodes > 1)}",
                "collect": lambda: f"collect {s.episodes} episodes from {s.run} (≥ {s.percentile:g}th pct.)",
                "vaf": lambda: f"VAF of {s.activations} ({s.method})",
                "fit": lambda: f"fit {s.method} to {s.activations}"
                               + (f", N = {s.n_synergies}" if s.n_synergies else f", VAF ≥ {s.vaf}"),
                "zeroshot": lambda: f"zero-shot {', '.join(s.runs)} on {', '.join(s.envs)}",
                "compare": lambda: f"compare {', '.join(s.groups)}",
                "dynamics-collect": lambda: f"collect {s.episodes:,} {s.policy} episodes of {s.env}",
                "dynamics-fit": lambda: f"fit a forward model {s.ensemble}x{s.hidden} to {s.transitions}",
                "dynamics-check": lambda: f"check {s.model} open loop, {s.episodes} episodes",
                "mpc": lambda: f"MPC ({s.optimizer}) on {s.model} · {s.env}"}[step.kind]()
    tags = [env.id]
    if env.delay:
        tags.append(f"delay {env.delay:g} s on {env.delay_on}")  # action, observation or both
    if env.history > 1:
        tags.append(f"history {env.history}")
    if env.sar or step.sar_ref:
        tags.append(f"synergies {step.sar_ref or Path(env.sar).name}, phi {env.phi:g}")
    return f"{what} · {', '.join(tags)}"


def run_study(recipe: Recipe, out: Path | None = None, console: Console | None = None,
              execution: Execution | None = None) -> dict[str, Any]:
    """Run every step of `recipe`, write the study's table, plots and summary.json.

    Args:
        execution: where the seeds of a train step with several seeds run (default: in
            parallel on this machine, one process per seed).

    Returns:
        The study summary (flat keys "<step>.<key>", plus "study_dir").
    """
    console = console or Console(stderr=True)
    execution = execution or Execution()
    from motorlab.sweeps.backends import check_execution

    check_execution(execution.backend, execution.address, execution.max_parallel)
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
    study_dir = prepare_run_dir(out, recipe.name)
    write_config(study_dir, {"recipe": recipe.name, "source": recipe.source, "steps": [s.name for s in recipe.steps]})
    t0 = time.perf_counter()
    outputs = _Outputs(study_dir)
    overlaps = Overlaps()
    if parallel_steps > 1:
        console.print(f"      train steps that need nothing from each other run at once, at most {parallel_steps}")
        results, overlaps = run_overlapped(
            recipe.steps, lambda step, detached, stop: _run_step(step, study_dir, outputs, console, execution,
                                                                 detached, stop),
            parallel_steps, console, lambda step: _train_progress(step, study_dir), _describe,
            lambda step: [plot_run(d) for d in _run_dirs(step, study_dir)])
    else:
        results = {}
        for i, step in enumerate(recipe.steps, 1):
            console.print(f"[bold][{i}/{len(recipe.steps)}][/bold] {step.name}: {_describe(step)}")
            t_step = time.perf_counter()
            results[step.name] = _run_step(step, study_dir, outputs, console, execution)
            console.print(f"      done in {time.perf_counter() - t_step:.1f} s")
    study_summary: dict[str, Any] = {"recipe": recipe.name, "description": recipe.description,
                                     "steps": [s.name for s in recipe.steps],
                                     "parallel_steps": parallel_steps,
                                     "wall_seconds": round(time.perf_counter() - t0, 2)}
    for name in (s.name for s in recipe.steps):
        study_summary.update({f"{name}.{k}": v for k, v in results[name].items()})
    _figures(recipe, results, study_dir)
    rows = [_cells(s, results[s.name], sorted(overlaps.beside.get(s.name, ()))) for s in recipe.steps]
    atomic_write_text(study_dir / "table.txt", plain_table(COLUMNS, rows))
    write_summary(study_dir, study_summary)
    console.print(rich_table(f"{recipe.name}: {recipe.description}" if recipe.description else recipe.name,
                             COLUMNS, rows, left=("step", "what", "notes")))
    build_report([study_dir], study_dir / "report.html")
    study_summary["study_dir"] = str(study_dir)
    return study_summary


def _train_progress(step: Step, study_dir: Path) -> tuple[int, int]:
    """Env steps a background train step has done so far (all its seeds), and its budget."""
    dirs = _run_dirs(step, study_dir)
    return sum(last_timesteps(d) for d in dirs), step.train.timesteps * len(dirs)


def _cells(step: Step, r: dict[str, Any], beside: list[str] = ()) -> list[str]:
    cells = _step_cells(step, r)
    if beside:  # its wall time was shared with these steps
        cells[-1] = "; ".join(x for x in (cells[-1], f"ran beside {', '.join(beside)}") if x)
    return cells


def _step_cells(step: Step, r: dict[str, Any]) -> list[str]:
    def fmt(v, f="{:,.1f}"):
        return "-" if v is None else f.format(v)

    if step.kind == "mpc":
        return [step.name, _describe(step), f"{fmt(r['return_mean'], '{:.2f}')} ± {fmt(r['return_std'], '{:.2f}')}",
                fmt(r.get("return_min"), "{:.2f}"), "-", "n/a", "-", _note(step, r)]
    if step.kind not in ("train", "evaluate"):
        return [step.name, _describe(step), "-", "-", "-", "n/a", "-", _note(step, r)]
    sts = r.get("steps_to_success", "n/a" if step.kind == "evaluate" else None)
    rate = r.get("train_success_rate_last100")
    # ± is the spread over evaluation episodes for one seed, over the seeds' means for several
    spread = f" ({r['seeds']} seeds)" if r.get("seeds") else ""
    return [step.name, _describe(step), f"{fmt(r.get('return_mean'))} ± {fmt(r.get('return_std'))}{spread}",
            fmt(r.get("return_min"), "{:,.0f}"), fmt(r.get("success_rate"), "{:.0%}"),
            sts if isinstance(sts, str) else (f"{sts:,.0f}" if sts is not None
                                              else "not solved" if step.train.until_solved else "-"),
            fmt(r.get("wall_seconds"), "{:.1f}"),
            "; ".join(x for x in (_iqm_note(r), f"training success (last 100 episodes) {rate:.0%}"
                                  if rate is not None else _falls_note(r)) if x)]


def _iqm_note(r: dict[str, Any]) -> str:
    """Several seeds: rliable's IQM of the return with its 95% bootstrap CI."""
    if r.get("return_iqm") is None:
        return ""
    return f"return IQM {r['return_iqm']:,.1f} [{r['return_iqm_ci_low']:,.1f}, {r['return_iqm_ci_high']:,.1f}]"


def _falls_note(r: dict[str, Any]) -> str:
    """Mean episode length and falls of the evaluation, where they were recorded."""
    if r.get("falls") is None or r.get("episode_length_mean") is None:
        return ""
    return f"mean length {r['episode_length_mean']:,.0f} steps, falls {r['falls']}/{r.get('episodes', '?')}"


def _note(step: Step, r: dict[str, Any]) -> str:
    if step.kind == "video":
        return ", ".join(f"{step.name}/{Path(v).name}" for v in r["videos"])
    if step.kind == "collect":
        return f"kept {r['episodes_kept']} episodes, {r['samples']:,} samples x {r['n_muscles']} muscles"
    if step.kind == "vaf":
        n = r["n_for_threshold"]
        return f"N = {n} reaches VAF {r['threshold']:.0%}" if n else f"no N reaches VAF {r['threshold']:.0%}"
    if step.kind == "fit":
        return f"{r['n_synergies']} synergies, VAF {r['vaf']:.1%}"
    if step.kind == "zeroshot":
        means = {k[: -len(".success_rate_mean")]: v for k, v in r.items() if k.endswith(".success_rate_mean")}
        return "; ".join(f"{k}: {v:.0%}" for k, v in means.items()) + " (success, mean over seeds)"
    if step.kind == "dynamics-collect":
        return f"{r['transitions']:,} transitions at {r['transitions_per_second']:,.0f}/s ({r['simulator']})"
    if step.kind == "dynamics-fit":
        return f"valid MSE {r['valid_mse']:.2e} (normalized delta), {r['epochs_run']} epochs, {r['wall_seconds']:.1f} s"
    if step.kind == "dynamics-check":
        tips = [(k.removeprefix("tip_error_mean_"), v) for k, v in r.items() if k.startswith("tip_error_mean_h")]
        if tips:
            return "open-loop fingertip error " + ", ".join(f"{h}: {v * 1000:.1f} mm" for h, v in tips)
        return "open-loop state NRMSE " + ", ".join(f"{k.removeprefix('state_nrmse_')}: {v:.3f}"
                                                    for k, v in r.items() if k.startswith("state_nrmse_h"))
    if step.kind == "mpc":
        return (f"final distance {r['final_distance_mean'] * 1000:.1f} mm (mean), "
                f"planning {r['plan_ms_median']:.2f} ms/step")
    return "plots/learning_curves.png"


COLUMNS = ["step", "what", "return (mean ± sd)", "min return", "success", "steps to success", "train s", "notes"]


def _figures(recipe: Recipe, results: dict[str, dict[str, Any]], study_dir: Path) -> None:
    scored = [s.name for s in recipe.steps if s.kind in ("train", "evaluate")]
    if scored:
        comparison_bars(scored, [results[n].get("return_mean") for n in scored], "evaluation return (mean)",
                        study_dir / "plots" / "returns.png", f"{recipe.name}: return of each step")
    trained = [s.name for s in recipe.steps if s.kind == "train"]
    if trained:
        comparison_bars(trained, [results[n].get("steps_to_success") for n in trained], "environment steps",
                        study_dir / "plots" / "steps_to_success.png", f"{recipe.name}: steps until consistently solved",
                        steps=True)
