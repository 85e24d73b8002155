"""SAR-RL against RL-E2E on the MyoSuite hand, with the learner that learns most per hour here, at the largest
budget an hour of this 2-core machine allows.

    .venv/bin/python benchmarks/sar_hand_scaled.py [--preset WINNER] [--scale K] [--seeds 100-104] [--keep DIR]

The study is the `sar-hand` recipe (Berg et al. 2023's protocol): play on myoHandReorient8-v0 ->
collect the muscle activations of its best episodes -> synergies (PCA -> ICA -> MinMax) -> SAR-RL on
myoHandReorient100-v0 in synergy space against RL-E2E on raw muscles at EQUAL env steps (RL-E2E's
budget = play + SAR-RL, the recipe's 1M + 1.5M = 2.5M) -> zero-shot on myoHandReorientID-v0 and
myoHandReorientOOD-v0. Every budget (training steps, collected episodes, the evaluation interval) is
the recipe's divided by K; SAR-RL and RL-E2E run every seed of --seeds (>= 5 per arm).

The learner: --preset, by default the winner on myoHandPoseRandom-v0 of benchmarks/learner_per_hour.py's
recorded headline (results/learner_per_hour.json). The scale: --scale, by default the smallest K whose
study fits ~60 min here: the study's env steps, 1M + S x 1.5M + S x 2.5M for S seeds, divided by K, over
its two chains at once, with 15% left for start-up, collection and evaluation. A chain's rate is what the
last recorded run of this study measured (results/sar_hand_scaled.json: its slower chain's env steps over
its seconds) where that run used the same learner, else the learner's one-core rate on the hand
(learner_per_hour.json) x CHAINS_SHARE: the two chains share the 2 cores with 4 env processes each, and
the one-core rate alone gave 73 min for an hour's plan (the run of 2026-11-29: chains at ~335 and ~366
env steps/s against the one-core 476).

Seeds: headline seeds (100+, benchmarks/provenance.py): no run on them chose the learner or the scale;
this needs committed code (run it from a git worktree). Development seeds (0-99) write a devlog line.

Measured, per arm and seed: the final evaluation's success (MyoSuite's "solved"), return and episode
length; per arm over seeds (the IQM from 4, a bootstrap CI from 5, the range) and the success episodes
pooled (Wilson); P(SAR-RL > RL-E2E) on success and on return (rliable; "all tied" where every seed ties);
the one-sided Mann-Whitney U test on the returns (exact; p <= 0.05 is the study's claim, reported
whichever way it goes); zero-shot success per seed on ID and OOD for each arm. What MyoSuite 3.0's own
re-extraction found, beside it: SAR-RL equal to RL-E2E on locomotion, ahead in 2 of 6 manipulation seeds.

Time: ~60 min at the default scale (set by the measured rate); --quick: K = 5000, 2 seeds a side, a few
minutes (a smoke run; development seeds 0-1 by default).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import tempfile
import time
from pathlib import Path

from provenance import Harness, SeedPlan, seed_list  # benchmarks/ is the script's folder
from sar_legs import compared, per_arm, science_target  # per-arm summaries, SAR-RL vs RL-E2E, the one-sided test

RECIPE = "sar-hand"
HAND_TASK = "myoHandPoseRandom-v0"  # learner_per_hour's hand task: its winner and its rate
STUDY_STEPS = {"play": 1_000_000, "sar-rl": 1_500_000, "rl-e2e": 2_500_000}
TARGET_MINUTES, OVERHEAD = 60.0, 0.15
# a chain's env steps/s beside the other chain, over the one-core rate: 335 / 476 in the run of 2026-11-29
# (results/sar_hand_scaled.json at eb6da51, sar-sac-fast), where no run of the learner was recorded
CHAINS_SHARE = 0.70
SEEDS = SeedPlan(development=range(0, 100), headline=range(100, 1000))
QUICK = {"scale": 5000, "seeds": [0, 1]}


def recorded_winner(results: Path) -> tuple[str, float]:
    """The hand task's winner in learner_per_hour.json and its median env steps/s on one core."""
    path = results / "learner_per_hour.json"
    if not path.is_file():
        raise SystemExit(f"{path} is not there: run benchmarks/learner_per_hour.py (screen, then confirm) first, "
                         "or give --preset and --scale")
    task = json.loads(path.read_text())["tasks"][HAND_TASK]
    winner = task["winner"]
    rates = sorted(task["contenders"][winner]["env_steps_per_second"])
    return winner, rates[len(rates) // 2]


def chain_rate(results: Path, preset: str, one_core: float) -> float:
    """env steps/s a chain of this study makes beside the other: the last recorded run's slower chain (play
    -> SAR-RL, or RL-E2E: their env steps over their seconds, all seeds) where it used `preset`, else
    `one_core` x CHAINS_SHARE."""
    path = results / "sar_hand_scaled.json"
    if path.is_file():
        run = json.loads(path.read_text())
        if run.get("learner") == preset:
            steps, seconds, n = run["env_steps_per_seed"], run["step_seconds"], len(run["seeds"])
            chains = (((steps["play"] + n * steps["sar-rl"]) / (seconds["play"] + seconds["sar-rl"])),
                      n * steps["rl-e2e"] / seconds["rl-e2e"])
            return min(chains)
    return one_core * CHAINS_SHARE


def scale_for(rate: float, seeds: int, minutes: float = TARGET_MINUTES, cores: int = 2) -> int:
    """The smallest K whose study (1M + seeds x (1.5M + 2.5M) env steps, divided by K) fits `minutes` on
    `cores` chains at `rate` env steps/s each (`chain_rate`), OVERHEAD of the time left for everything else."""
    steps = STUDY_STEPS["play"] + seeds * (STUDY_STEPS["sar-rl"] + STUDY_STEPS["rl-e2e"])
    return max(1, math.ceil(steps / (rate * cores * minutes * 60 * (1 - OVERHEAD))))


def given_fields(preset: str, scale: int, seeds: list[int]) -> dict:
    """The recipe's fields set for this run: the learner, every budget / scale, the seeds."""
    from motorlab.recipes import load_recipe

    full = {s.name: s.fields for s in load_recipe(RECIPE).steps}
    given: dict = {"preset": preset, "eval_every": max(500, full["play"]["eval_every"] // scale),
                   "play.seed": seeds[0], "sar-rl.seeds": seeds, "rl-e2e.seeds": seeds}
    for step in ("play", "sar-rl"):
        given[f"{step}.timesteps"] = max(500, STUDY_STEPS[step] // scale)
    given["rl-e2e.timesteps"] = given["play.timesteps"] + given["sar-rl.timesteps"]  # equal env steps, floors included
    for field, floor in (("episodes", 10), ("preview", 5)):
        given[f"collect.{field}"] = max(floor, round(full["collect"][field] / scale))
    given["zeroshot.episodes"] = max(20, round(full["zeroshot"]["episodes"] / scale))
    if not replay_buffer(preset):  # the recipe's SAR-RL warm-up (learning_starts 5000) is an off-policy setting
        given["sar-rl.hyperparams"] = {}
    return given


def replay_buffer(preset: str) -> bool:
    """Whether the preset's learner learns from a replay buffer (SAC, CrossQ: takes learning_starts)."""
    from motorlab import algos
    from motorlab.algos.base import OffPolicy
    from motorlab.rl.config import PRESETS

    if preset not in PRESETS:
        raise SystemExit(f"unknown preset {preset!r}; presets: {', '.join(PRESETS)}")
    return isinstance(algos.get(PRESETS[preset]["algo"]), OffPolicy)


def zero_shot(study: Path, arm: str) -> dict:
    """Each seed's zero-shot success on ID and OOD (the zeroshot step's summary)."""
    summary = json.loads((study / "zeroshot" / "summary.json").read_text())
    out: dict[str, dict] = {}
    for key, value in summary.items():  # "<arm>/seed<k>.<env>.success_rate"
        if key.startswith(f"{arm}/seed") and key.endswith(".success_rate"):
            run, env, _ = key.rsplit(".", 2)
            out.setdefault(env, {})[run.split("/", 1)[1]] = value
    return out


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--preset", default=None, help="the learner (default: learner_per_hour.json's winner on the hand)")
    p.add_argument("--scale", type=int, default=None, help="divide every budget by this (default: fit ~60 min)")
    p.add_argument("--seeds", type=seed_list, default=None, help="SAR-RL's and RL-E2E's seeds (default 100-104)")
    p.add_argument("--keep", type=Path, default=None, help="write the study here (an interrupted one continues)")
    p.add_argument("--quick", action="store_true", help="a smoke run: " + json.dumps(QUICK))
    args = p.parse_args(argv)
    results = Path(__file__).resolve().parent / "results"
    seeds = args.seeds or (QUICK["seeds"] if args.quick else list(range(100, 105)))
    rate = None
    if args.preset is None or (args.scale is None and not args.quick):
        winner, one_core = recorded_winner(results)
        args.preset = args.preset or winner
        rate = chain_rate(results, args.preset, one_core)
    scale = args.scale or (QUICK["scale"] if args.quick else scale_for(rate, len(seeds)))
    given = given_fields(args.preset, scale, seeds)
    settings = {"recipe": RECIPE, "preset": args.preset, "scale": scale, "given": given,
                "rate_env_steps_per_second": rate}
    run = Harness("sar_hand_scaled", seeds=SEEDS).start(seeds, settings, log="sar_hand_scaled" + ("-quick" if args.quick else ""))
    from motorlab.recipes import load_recipe
    from motorlab.runs import read_json
    from motorlab.studies import run_study

    print(f"[sar-hand-scaled] {args.preset} at 1/{scale} of sar-hand, seeds {seeds} ({run.mode})", file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        study = args.keep or Path(tmp) / "study"
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(sys.stderr):  # the study's progress and table; stdout is the JSON
            step_seconds = run_study(load_recipe(RECIPE, given), study)["step_seconds"]
        wall = time.perf_counter() - t0
        arms = {a: per_arm([read_json(f) for f in sorted((study / a).glob("seed*/summary.json"))])
                for a in ("sar-rl", "rl-e2e")}
        zero = {a: zero_shot(study, a) for a in arms}
    from motorlab.intervals import p_better

    versus = compared(arms["sar-rl"]["return"], arms["rl-e2e"]["return"])
    result = {
        "recipe": RECIPE, "learner": args.preset, "scale": scale, "seeds": seeds, "given": given,
        "env_steps_per_seed": {a: given[f"{a}.timesteps"] for a in ("play", "sar-rl", "rl-e2e")},
        "wall_seconds": round(wall, 1), "step_seconds": step_seconds, "arms": arms, "zero_shot_success": zero,
        "sar_rl_vs_rl_e2e_return": versus,
        "p_sar_better_success": p_better(arms["sar-rl"]["success"]["per_seed"],
                                         arms["rl-e2e"]["success"]["per_seed"]).to_json(),
        "science_target": science_target(arms["sar-rl"]["return"], arms["rl-e2e"]["return"]),
        "myosuite_3_reextraction": "MyoSuite 3.0's own re-extraction notes: SAR-RL equal to RL-E2E on locomotion, "
                                   "ahead in 2 of 6 manipulation seeds",
    }
    run.finish(result, file="sar_hand_scaled" + ("-quick" if args.quick else ""))


if __name__ == "__main__":  # env subprocesses re-import this file
    main()
