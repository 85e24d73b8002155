"""SAR beyond muscles: SAR-RL vs RL-E2E at equal env steps on a robot, over the recipe's seeds (5 a side).

Runs the bundled `sar-ant` study (motorlab/recipes/sar-ant.toml; its comments say why this pair
of tasks): SAC plays Ant-v5 running forward (60k env steps), `collect --signal auto` records the
8 actuator controls MuJoCo applied (data.ctrl) of its good episodes (mean actions), `fit` keeps the synergies
explaining 80% of their variance, then on Ant running backward (forward_reward_weight = -1)
SAR-RL (synergies only, phi = 1) trains 60k env steps and RL-E2E 120k (= play + SAR-RL), the
recipe's seeds each (0-4; this docstring's measurements below are from when it ran 0, 1, 2); both arms' policies are then evaluated zero-shot from starts three times as
perturbed (reset_noise_scale = 0.3). 600k env steps in all, SAC with [64, 64] nets and one
gradient step per 4 env steps, two trainings at once: 15 min on this 2-core machine (913 s
measured at full scale; the target is <= 30 min).

Reported: each arm's final evaluation return (mean of 5 deterministic episodes) per seed, with
rliable's IQM and 95% stratified-bootstrap CI, the zero-shot returns likewise, and SAR-RL against
RL-E2E: the difference of the IQMs and their ratio (where both are positive), whichever way it
goes. Ant has no success flag: returns it is.

Measured at full scale with 5 seeds a side (2026-11-28, results/sar_robot.json): 1,777 s (target
<= 1,800 s: met). 5 synergies (VAF 80.5%). SAR-RL IQM -54.5 [-149.4, -12.2], RL-E2E -5.6 [-12.8,
3.2]; P(SAR-RL > RL-E2E) 0.08 [0.00, 0.32]; Mann-Whitney p = 0.99: the science target is not met,
RL-E2E is ahead. Zero-shot -34.9 vs -24.0, P 0.32 [0.00, 0.68].
Earlier, with 3 seeds a side (2026-11-25): 913 s, both arms failing at these budgets (SAR-RL's 3
seeds' range [-111, -11], RL-E2E's [-16, -1]; a 3-seed bracket is their range, not a 95% CI).
At 1/8 scale an earlier run went the other way: early in learning the result turns on falls, not on gait.

Usage:  .venv/bin/python benchmarks/sar_robot.py [--scale K]
        (or SAR_ROBOT_SCALE=K): every budget divided by K (play, SAR-RL, RL-E2E env steps, SAC
        warm-up, evaluation interval, collected episodes) to try it in minutes; the JSON says
        which scale ran. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

RECIPE = "sar-ant"
# Budget fields of the recipe divided by --scale, each with the smallest value it may take.
SCALED = {"timesteps": 500, "learning_starts": 200, "eval_every": 1000, "episodes": 3, "preview": 3}


def scaled_recipe(scale: int, folder: Path) -> Path:
    """The bundled recipe with its budgets divided by `scale` (unchanged for 1), written to `folder`."""
    from motorlab.recipes import find_recipe

    text = find_recipe(RECIPE).read_text()
    for key, floor in SCALED.items():
        text = re.sub(rf"\b{key} = (\d+)", lambda m, k=key, f=floor: f"{k} = {max(f, int(m.group(1)) // scale)}", text)
    path = folder / f"{RECIPE}.toml"
    path.write_text(text)
    return path


def seed_values(study: Path, step: str, key: str) -> list[float]:
    """`key` of each seed's summary.json of `step` (seed0, seed1, ...)."""
    runs = sorted((study / step).glob("seed*/summary.json"))
    return [float(json.loads(p.read_text())[key]) for p in runs]


def arm(values: list[float]) -> dict:
    """Per-seed values over seeds (motorlab.intervals): the IQM from 4 seeds (else the mean), a 95%
    stratified-bootstrap CI from 5 seeds (else none), the seeds' range, and what the shown interval
    is ("text": the CI from 5 seeds, else the range, named so)."""
    from motorlab.intervals import across_seeds

    summary = across_seeds(values)
    return {"per_seed": [round(v, 2) for v in values], "statistic": summary.statistic, "value": round(summary.value, 2),
            "ci95": [round(x, 2) for x in summary.ci] if summary.ci else None,
            "range": [round(x, 2) for x in summary.range] if summary.range else None, "ci_method": summary.method,
            "text": summary.text(lambda v: f"{v:.2f}")}


def ratio(a: dict, b: dict) -> float | None:
    """SAR-RL's IQM over RL-E2E's; None unless both are positive (a ratio of negative returns
    reads backwards: -45 / -8 = 5.8 for the worse arm). The difference is reported beside it."""
    return round(a["value"] / b["value"], 3) if a["value"] > 0 and b["value"] > 0 else None


def compared(a: dict, b: dict) -> dict:
    """How SAR-RL (a) stands against RL-E2E (b): ratio, difference, which is higher, and P(SAR-RL >
    RL-E2E) over their seeds (rliable's probability of improvement; its interval from 5 seeds a side;
    "all tied" where every seed of both arms has the same value)."""
    from motorlab.intervals import p_better

    better = p_better(a["per_seed"], b["per_seed"])
    return {"ratio_sar_over_e2e": ratio(a, b), "difference_sar_minus_e2e": round(a["value"] - b["value"], 2),
            "higher": "sar_rl" if a["value"] > b["value"] else "rl_e2e" if b["value"] > a["value"] else "tie",
            "p_sar_better": better.to_json()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scale", type=int, default=int(os.environ.get("SAR_ROBOT_SCALE", "1")),
                        help="divide every budget by this (default 1: the bundled study)")
    parser.add_argument("--keep", type=Path, default=None, help="write the study here instead of a temporary folder")
    args = parser.parse_args()
    recorder = Recorder("sar_robot")  # the git state and load, read as the run starts
    with tempfile.TemporaryDirectory() as tmp:
        recipe = scaled_recipe(max(1, args.scale), Path(tmp))
        study = args.keep or Path(tmp) / "study"
        started = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "motorlab", "run", str(recipe), "--out", str(study)],
                              capture_output=True, text=True)
        wall = time.perf_counter() - started
        if proc.returncode != 0:
            raise SystemExit(f"the study failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
        from motorlab.recipes import load_recipe

        loaded = {s.name: s for s in load_recipe(recipe).steps}
        steps = {name: s.settings for name, s in loaded.items()}
        seeds = len(loaded["sar-rl"].seeds or [0])
        collect = json.loads((study / "collect" / "summary.json").read_text())
        fit = json.loads((study / "fit" / "summary.json").read_text())
        sar = arm(seed_values(study, "sar-rl", "eval_return_mean"))
        e2e = arm(seed_values(study, "rl-e2e", "eval_return_mean"))
        zs_sar = arm(seed_values(study, "zeroshot-sar-rl", "return_mean"))
        zs_e2e = arm(seed_values(study, "zeroshot-rl-e2e", "return_mean"))
    play, sar_steps, e2e_steps = (steps[k].timesteps for k in ("play", "sar-rl", "rl-e2e"))
    versus = compared(sar, e2e)
    out = {
        "benchmark": "sar_robot", "recipe": RECIPE, "scale": args.scale, "seeds": seeds,
        "play_task": "Ant-v5 (forward)", "task": "Ant-v5, forward_reward_weight = -1 (backward)",
        "zero_shot_variant": "the backward task with reset_noise_scale = 0.3",
        "budgets_env_steps": {"play": play, "sar_rl_per_seed": sar_steps, "rl_e2e_per_seed": e2e_steps,
                              "sar_rl_total_per_seed_with_play": play + sar_steps,
                              "study_total": play + seeds * (sar_steps + e2e_steps)},
        "sac": "sar-sac preset, nets [64, 64], 1 gradient step per 4 env steps, 1 torch thread, 2 trainings at once",
        "signal": collect["signal"], "motors": collect["n_muscles"], "synergies": fit["n_synergies"],
        "vaf": round(fit["vaf"], 3),
        "metric": "final evaluation return (5 deterministic episodes; zero-shot: the evaluate step's episodes)",
        "sar_rl": sar, "rl_e2e": e2e, **versus,
        "zero_shot": {"sar_rl": zs_sar, "rl_e2e": zs_e2e, **compared(zs_sar, zs_e2e)},
        "wall_seconds": round(wall, 1), "cpus": os.cpu_count(),
        "targets": {"wall": {"target": "full scale in <= 1800 s on this 2-core machine",
                             "met": wall <= 1800 if args.scale == 1 else None},
                    "sar_rl_beats_rl_e2e": science_target(sar, e2e)},
    }
    recorder.record(out)


def science_target(sar: dict, e2e: dict) -> dict:
    """The study's claim, SAR-RL learns the task better than RL-E2E at equal env steps, tested on
    the seeds' final returns with scipy's one-sided Mann-Whitney U test (exact): met where p <= 0.05.
    With 3 seeds a side the smallest p is 1/20 = 0.05 (every SAR-RL seed above every RL-E2E seed);
    with 5, 1/252."""
    from scipy.stats import mannwhitneyu

    test = mannwhitneyu(sar["per_seed"], e2e["per_seed"], alternative="greater", method="exact")
    return {"target": "SAR-RL's final returns above RL-E2E's: one-sided Mann-Whitney U, p <= 0.05",
            "u": float(test.statistic), "p_value": float(test.pvalue), "met": bool(test.pvalue <= 0.05)}

if __name__ == "__main__":
    main()
