"""`motorlab run RECIPE`: each step writes its own run folder inside the study folder.

Re-running a study into the same folder skips steps that finished with the same
settings, so an interrupted study resumes where it stopped.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from motorlab.evaluate import evaluate_step
from motorlab.recipes import Recipe, Step
from motorlab.report.plots import comparison_bars
from motorlab.report.run import plot_run
from motorlab.rl.train import train
from motorlab.runs import atomic_write_text, finished_with, prepare_run_dir, read_json, write_config, write_summary

# Headline keys copied from each step into the study's summary.json as "<step>.<key>".
HEADLINE = ("return_mean", "return_std", "return_min", "success_rate", "steps_to_success", "timesteps", "wall_seconds")


def _step_config(step: Step, study_dir: Path) -> dict[str, Any]:
    """The settings a step's run folder records (as `motorlab train` / `evaluate` write them)."""
    if step.kind == "train":
        return step.train.model_dump()
    ev = step.evaluate
    policy = str(study_dir / step.policy_ref) if step.policy_ref else ev.policy
    return {"policy": policy, "episodes": ev.episodes, "seed": ev.seed, "env": ev.env.model_dump()}


def _headline(step: Step, s: dict[str, Any]) -> dict[str, Any]:
    """Flat headline numbers of one step (training steps report their final evaluation)."""
    get = (lambda k: s.get(f"eval_{k}", s.get(k))) if step.kind == "train" else s.get
    return {k: get(k) for k in HEADLINE if get(k) is not None or k == "steps_to_success" and step.kind == "train"}


def _describe(step: Step) -> str:
    if step.kind == "train":
        c = step.train
        what = f"{c.preset or c.algo}" + (" until solved" if c.until_solved else f" {c.timesteps:,} steps")
        env = c.env
    else:
        what = f"evaluate {step.evaluate.policy}"
        env = step.evaluate.env
    tags = [env.id]
    if env.delay:
        tags.append(f"delay {env.delay:g} s")
    if env.history > 1:
        tags.append(f"history {env.history}")
    return f"{what} · {', '.join(tags)}"


def run_study(recipe: Recipe, out: Path | None = None, console: Console | None = None) -> dict[str, Any]:
    """Run every step of `recipe`, write the study's table, plots and summary.json.

    Returns:
        The study summary (flat keys "<step>.<key>", plus "study_dir").
    """
    console = console or Console(stderr=True)
    study_dir = prepare_run_dir(out, recipe.name)
    write_config(study_dir, {"recipe": recipe.name, "source": recipe.source,
                             "steps": {s.name: _step_config(s, study_dir) for s in recipe.steps}})
    t0 = time.perf_counter()
    results: dict[str, dict[str, Any]] = {}
    for i, step in enumerate(recipe.steps, 1):
        step_dir = study_dir / step.name
        config = _step_config(step, study_dir)
        console.print(f"[bold][{i}/{len(recipe.steps)}][/bold] {step.name}: {_describe(step)}")
        if finished_with(step_dir, config):
            console.print("      already done with these settings; kept")
            summary = read_json(step_dir / "summary.json")
        elif step.kind == "train":
            summary = train(step.train, step_dir)
        else:
            summary = evaluate_step(config["policy"], step.evaluate.env, config["episodes"], config["seed"], step_dir)
        plot_run(step_dir)
        results[step.name] = _headline(step, summary)
    study_summary: dict[str, Any] = {"recipe": recipe.name, "steps": [s.name for s in recipe.steps],
                                     "wall_seconds": round(time.perf_counter() - t0, 2)}
    for name, head in results.items():
        study_summary.update({f"{name}.{k}": v for k, v in head.items()})
    _figures(recipe, results, study_dir)
    rows = [_cells(s, results[s.name]) for s in recipe.steps]
    atomic_write_text(study_dir / "table.txt", _plain_table(rows))
    write_summary(study_dir, study_summary)
    console.print(_table(recipe, rows))
    study_summary["study_dir"] = str(study_dir)
    return study_summary


def _cells(step: Step, r: dict[str, Any]) -> list[str]:
    def fmt(v, f="{:,.1f}"):
        return "-" if v is None else f.format(v)

    sts = r.get("steps_to_success", "n/a" if step.kind == "evaluate" else None)
    return [step.name, _describe(step), f"{fmt(r.get('return_mean'))} ± {fmt(r.get('return_std'))}",
            fmt(r.get("return_min"), "{:,.0f}"), fmt(r.get("success_rate"), "{:.0%}"),
            sts if isinstance(sts, str) else ("not solved" if sts is None else f"{sts:,}"),
            fmt(r.get("wall_seconds"), "{:.1f}")]


COLUMNS = ["step", "what", "return (mean ± std)", "min return", "success", "steps to success", "train s"]


def _table(recipe: Recipe, rows: list[list[str]]) -> Table:
    table = Table(title=f"{recipe.name}: {recipe.description}" if recipe.description else recipe.name)
    for c in COLUMNS:
        table.add_column(c, justify="left" if c in ("step", "what") else "right")
    for row in rows:
        table.add_row(*row)
    return table


def _plain_table(rows: list[list[str]]) -> str:
    rows = [COLUMNS, *rows]
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(COLUMNS))]
    return "\n".join("  ".join(str(c).ljust(w) for c, w in zip(r, widths)) for r in rows) + "\n"


def _figures(recipe: Recipe, results: dict[str, dict[str, Any]], study_dir: Path) -> None:
    names = [s.name for s in recipe.steps]
    comparison_bars(names, [results[n].get("return_mean") for n in names], "evaluation return (mean)",
                    study_dir / "plots" / "returns.png", f"{recipe.name}: return of each step")
    trained = [s.name for s in recipe.steps if s.kind == "train"]
    if trained:
        comparison_bars(trained, [results[n].get("steps_to_success") for n in trained], "environment steps",
                        study_dir / "plots" / "steps_to_success.png", f"{recipe.name}: steps until consistently solved")
