"""Steps-to-success on InvertedPendulum-v5: Stable-Baselines3 PPO defaults vs motorlab's
`fast` preset, plain and with 0.2 s actuation + perception delay (low-pass filters
on both action and observation), 5 seeds, one process.

"Solved" is the same rule for both: 10 deterministic evaluation episodes (fixed
seeds) all reach the maximum return of 1000, checked after every PPO update
(every 2,048 steps) and after every refit of motorlab's model. Steps are the env
steps that trained the first policy that passed; wall time is the whole training
run, evaluations included.

SB3 on the delayed env gets 10-frame observation history (it needs it); motorlab's
fast preset remembers its own past actions instead.

Usage:  .venv/bin/python benchmarks/pendulum_steps_to_success.py [--seeds 5]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

from motorlab.kinds.train import TRAIN
from motorlab.rl.config import resolve
from motorlab.rl.train import train
from motorlab.stats import steps_ratio, steps_to_threshold

TARGETS = {"plain_median_steps": 5000, "plain_wall_ratio_max": 0.5, "delayed_median_steps": 8000}


def run(settings: dict, seeds: list[int], root: Path, tag: str) -> dict:
    steps, wall = [], []
    for seed in seeds:
        s = train(resolve({**settings, "seed": seed, "until_solved": True, "progress": False}), root / f"{tag}-{seed}", kind=TRAIN.name)
        steps.append(s["steps_to_success"])
        wall.append(s["wall_seconds"])
        print(f"{tag} seed {seed}: steps_to_success={s['steps_to_success']} wall={s['wall_seconds']:.2f}s", file=sys.stderr)
    # an unsolved seed is censored at its budget, never counted as if it had solved there
    reached = steps_to_threshold(steps, settings["timesteps"])
    return {
        "steps_to_success": steps,
        "budget": settings["timesteps"],
        "wall_seconds": wall,
        "solved_seeds": reached.solved,
        "median_steps": reached.median,  # Kaplan-Meier; None: above the budget (fewer than half solved)
        "median_above": reached.median_above,
        "median_text": reached.text,
        "median_wall_seconds": round(statistics.median(wall), 3),
    }


def reached(arm: dict):
    return steps_to_threshold(arm["steps_to_success"], arm["budget"])


def compare(peer: dict, ours: dict) -> dict:
    return {
        "sb3_ppo_defaults": peer,
        "motorlab_fast": ours,
        # ours / the peer's: exact, or a bound where a median is censored
        "steps_ratio_motorlab_over_sb3": steps_ratio(reached(peer), reached(ours)).to_json(),
        "wall_ratio_motorlab_over_sb3": round(ours["median_wall_seconds"] / peer["median_wall_seconds"], 4),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--env", default="InvertedPendulum-v5")
    args = parser.parse_args()
    recorder = Recorder("pendulum_steps_to_success")  # the git state and load, read as the run starts
    seeds = list(range(args.seeds))
    env, delayed = {"id": args.env}, {"id": args.env, "delay": 0.2}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        plain = compare(run({"preset": "sb3-ppo", "env": env, "timesteps": 200_000}, seeds, root, "sb3-plain"),
                        run({"preset": "fast", "env": env, "timesteps": 20_000}, seeds, root, "fast-plain"))
        delay = compare(run({"preset": "sb3-ppo", "env": {**delayed, "history": 10}, "timesteps": 200_000}, seeds, root, "sb3-delay"),
                        run({"preset": "fast", "env": delayed, "timesteps": 20_000}, seeds, root, "fast-delay"))
    result = {
        "benchmark": "pendulum_steps_to_success",
        "env": args.env,
        "seeds": seeds,
        "solve_rule": "10 deterministic episodes all at return 1000",
        "torch_threads": 1,
        "plain": plain,
        "delayed_tau_0.2s_action_and_observation": delay,
        "targets": TARGETS,
        "met": {
            # None: the censoring leaves it open (the median is above a budget below the target)
            "plain_median_steps": reached(plain["motorlab_fast"]).at_most(TARGETS["plain_median_steps"]),
            "plain_wall_ratio": plain["wall_ratio_motorlab_over_sb3"] <= TARGETS["plain_wall_ratio_max"],
            "delayed_median_steps": reached(delay["motorlab_fast"]).at_most(TARGETS["delayed_median_steps"]),
        },
    }
    recorder.record(result)


if __name__ == "__main__":
    main()
