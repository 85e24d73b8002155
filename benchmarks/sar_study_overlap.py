"""Wall time of the sar-hand study: its steps one after another vs its two chains at once.

The study is two chains that need nothing from each other: play -> collect -> fit -> SAR-RL,
and RL-E2E. `parallel_steps = 2` (the bundled recipe's setting) trains them at the same
time, each in its own process. This runs the bundled `sar-hand` recipe with every budget
divided by --scale (same settings otherwise: sar-sac-fast, phi 0.66, zero-shot ID/OOD),
first with parallel_steps = 1, then 2, in this one process, and reports both wall times,
their ratio and whether every step gave the same numbers both ways.

Budgets are scaled, not the settings: at scale 40 the study trains 125k env steps, the
full one 5M. Early training has short episodes (the object drops; resets cost more), so
the ratio at full scale may differ; the issue notes combine it with full-study timings.

Usage:  .venv/bin/python benchmarks/sar_study_overlap.py [--scale 40]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import tomllib
from pathlib import Path

import tomli_w
from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path


def scaled_recipe(scale: float) -> str:
    """The bundled sar-hand recipe with every budget (env steps, episodes) divided by `scale`, one
    seed per arm."""
    from motorlab.recipes import bundled

    data = tomllib.loads(bundled()["sar-hand"].read_text())
    data["name"] = f"sar-hand-scale{scale:g}"
    for step in data["steps"]:
        # one seed per arm: this measures how the two chains overlap, not the comparison's spread
        step.pop("seeds", None)
        if "timesteps" in step:
            step["timesteps"] = max(2000, int(step["timesteps"] / scale))
        for key in ("episodes", "preview"):
            if key in step:
                step[key] = max(20, int(step[key] / scale))
    return tomli_w.dumps(data)


def main() -> None:
    from motorlab.recipes import parse_recipe
    from motorlab.studies import Execution, run_study

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scale", type=float, default=40, help="divide every budget by this (default 40)")
    args = parser.parse_args()
    recorder = Recorder("sar_study_overlap")  # the git state and load, read as the run starts
    recipe = parse_recipe(scaled_recipe(args.scale), f"sar-hand / {args.scale:g}")
    out = {"benchmark": "sar_study_overlap", "recipe": "sar-hand", "scale": args.scale,
           "env_steps": sum(s.settings.timesteps for s in recipe.steps if s.kind.trains)}
    summaries = {}
    # progress bars and tables to stderr: stdout is the JSON
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(sys.stderr):
        for k in (1, 2):
            summaries[k] = run_study(recipe, Path(tmp) / f"parallel{k}", execution=Execution(parallel_steps=k))
    steps = {k: summaries[1][k] for k in summaries[1] if k.split(".")[-1] in ("return_mean", "success_rate", "n_synergies")
             or k.endswith(".success_rate")}
    out.update({
        "sequential_seconds": summaries[1]["wall_seconds"],
        "parallel_seconds": summaries[2]["wall_seconds"],
        "speedup": round(summaries[1]["wall_seconds"] / summaries[2]["wall_seconds"], 3),
        "step_wall_seconds": {k: {"sequential": summaries[1].get(f"{s.name}.wall_seconds"),
                                  "parallel": summaries[2].get(f"{s.name}.wall_seconds")}
                              for k, s in ((s.name, s) for s in recipe.steps if s.kind.trains)},
        "same_numbers": {k: summaries[2].get(k) for k in steps} == steps,
        "numbers_compared": len(steps),
    })
    recorder.record(out)


if __name__ == "__main__":  # env subprocesses re-import this file
    main()
