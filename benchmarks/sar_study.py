"""SAR-RL's reference SAC against `sar-sac-fast`: speed on the hand, learning per env step on a smaller body.

Two parts, in one run, one JSON object (benchmarks/results/sar_study.json):

1. **Speed** (`--steps`, default 4000): trains in synergy space on myoHandReorient100-v0
   (phi = 0.66, the SAR published with MyoSuite, imported with --trust from ../shared/data) for a
   short budget with each setting, in this one process, and reports env steps per second once
   learning runs (timed from metrics.csv after the warm-up; evaluation switched off) and the hours
   the full sar-hand study (1M play + 1.5M SAR-RL + 2.5M RL-E2E = 5M env steps) would take at that
   rate. Target: the study in <= 2 h.
2. **Learning per env step** (`--learn-steps`, default 30000; `--learn-steps 0` skips it): the
   reference SAC (`sar-sac`: one gradient step per env step) and `sar-sac-fast` (the same SAC, 4 env
   processes, one gradient step per 25 env steps) train from scratch for the same env steps on a
   MyoSuite task where the reference learns within that budget (`--learn-env`, default
   myoFingerPoseRandom-v0, chosen by measuring: the reference's success there is ~55% after 5k env
   steps and still rising, where on myoElbowPose1D6MRandom-v0 it is 100% at 5k, too easy to tell the
   two apart), `--learn-seeds` seeds each (default 3), two trainings at a time, one math thread each.
   Per arm: the final evaluation's success rate (MyoSuite's "solved" at any step, `--learn-episodes`
   deterministic episodes per seed) and return, per seed, with the across-seed mean and its
   interval where the seeds allow one (motorlab.intervals), the episodes pooled over the seeds with
   their Wilson interval, P(fast > reference) with its interval, and each arm's evaluation curve.
   Target: sar-sac-fast's success at equal env steps >= the reference's (the mean over seeds):
   the evidence that the 1/25 update ratio keeps learning per step. Reported whichever way it goes.

Usage:  .venv/bin/python benchmarks/sar_study.py [--steps 4000] [--learn-steps 30000] [--learn-seeds 3]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

STUDY_STEPS = 1_000_000 + 1_500_000 + 2_500_000
PUBLISHED = Path(__file__).resolve().parents[2] / "shared" / "data" / "myosuite_sar_pretrained" / "manipulation"

CANDIDATES = {
    # the reference: one gradient step per env step
    "reference_sac": {"preset": "sar-sac-synergy", "hyperparams": {"learning_starts": 1000}},
    # motorlab's choice for sar-hand: the same SAC, 4 env processes, 1 gradient step per 25 env steps
    "sar_sac_fast": {"preset": "sar-sac-fast", "hyperparams": {"learning_starts": 1000}},
    # on-policy, two env processes (fast, but did not learn Reorient8 in 300k steps)
    "ppo_2_envs": {"algo": "ppo", "n_envs": 2, "normalize": True, "lr": "linear:3e-4,0",
                   "hyperparams": {"n_steps": 1024, "batch_size": 256}},
}


def steady_rate(run_dir: Path, warm_up: int) -> float:
    """Env steps per second once learning runs (after SAC's learning_starts / PPO's first rollout),
    from the episode rows of metrics.csv."""
    from motorlab.runs import read_metrics

    rows = [r for r in read_metrics(run_dir) if r["timesteps"] >= warm_up and r["episode_return"] == r["episode_return"]]
    if len(rows) < 2:
        raise SystemExit(f"{run_dir}: too few episodes after warm-up; give it more env steps (--steps, --chain-steps)")
    return (rows[-1]["timesteps"] - rows[0]["timesteps"]) / (rows[-1]["wall_seconds"] - rows[0]["wall_seconds"])


def main() -> None:
    from motorlab.api.synergies import import_sklearn
    from motorlab.kinds.train import TRAIN
    from motorlab.rl.config import resolve
    from motorlab.rl.train import train

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4000, help="env steps per setting (the first 1000-2048 warm up)")
    parser.add_argument("--learn-env", default="myoFingerPoseRandom-v0", help="the learning part's MyoSuite task")
    parser.add_argument("--learn-steps", type=int, default=30000, help="env steps per seed and arm (0: skip)")
    parser.add_argument("--learn-seeds", type=int, default=3, help="seeds per arm")
    parser.add_argument("--learn-episodes", type=int, default=50, help="final evaluation episodes per seed")
    parser.add_argument("--eval-every", type=int, default=5000, help="env steps between the curves' evaluations")
    parser.add_argument("--keep", type=Path, default=None, help="write the learning part's runs here (resumable)")
    args = parser.parse_args()
    recorder = Recorder("sar_study")  # the git state and load, read as the run starts
    learning = learn(args) if args.learn_steps > 0 else None
    out = {"benchmark": "sar_study", "env": "myoHandReorient100-v0", "phi": 0.66, "steps_per_setting": args.steps,
           "study_env_steps": STUDY_STEPS, "settings": {}}
    with tempfile.TemporaryDirectory() as tmp:
        sar = Path(tmp) / "sar.npz"
        import_sklearn(PUBLISHED, trust=True, out=sar)
        for name, settings in CANDIDATES.items():
            cfg = resolve({**settings, "env": {"id": "myoHandReorient100-v0", "sar": str(sar), "phi": 0.66},
                           "timesteps": args.steps, "eval_every": 10**9, "progress": False, "solve_episodes": 1})
            s = train(cfg, Path(tmp) / name, kind=TRAIN.name)
            rate = steady_rate(Path(tmp) / name, warm_up=1000 if cfg.algo == "sac" else 2048)
            out["settings"][name] = {"env_steps": s["timesteps"], "wall_seconds": s["wall_seconds"],
                                     "env_steps_per_second_after_warm_up": round(rate, 1),
                                     "projected_study_hours": round(STUDY_STEPS / rate / 3600, 2)}
            print(f"{name}: {rate:.1f} env steps/s", file=sys.stderr)
    key = "env_steps_per_second_after_warm_up"
    ref = out["settings"]["reference_sac"][key]
    out["speedup_over_reference"] = {k: round(v[key] / ref, 2) for k, v in out["settings"].items()}
    out["target"] = "full sar-hand study <= 2 h with success >= reference at equal env steps"
    out["speed_part_met_by"] = [k for k, v in out["settings"].items() if v["projected_study_hours"] <= 2.0]
    out["learning"] = learning
    out["targets"] = {
        "speed": {"target": "sar_sac_fast: the full sar-hand study in <= 2 h on this machine",
                  "met": "sar_sac_fast" in out["speed_part_met_by"]},
        "learning": learning["target"] if learning else {"target": "not measured (--learn-steps 0)", "met": None},
    }
    recorder.record(out)


# The learning part's two arms: motorlab train options on top of the task and budget. One math
# thread each, two trainings at a time on the two cores.
ARMS = {"reference_sac": ["--preset", "sar-sac"],
        "sar_sac_fast": ["--preset", "sar-sac-fast", "--torch-threads", "1"]}


def train_run(args: argparse.Namespace, arm: str, seed: int, folder: Path) -> Path:
    """One seed of one arm (kept when a finished run is already there)."""
    out = folder / arm / f"seed{seed}"
    if (out / "summary.json").is_file():
        return out
    cmd = [sys.executable, "-m", "motorlab", "train", args.learn_env, "--algo", "sac", *ARMS[arm],
           "--timesteps", str(args.learn_steps), "--seed", str(seed), "--eval-every", str(args.eval_every),
           "--solve-episodes", str(args.learn_episodes), "--torch-threads", "1", "--no-progress", "--out", str(out)]
    started = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{arm} seed {seed} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    print(f"{arm} seed {seed}: {time.perf_counter() - started:.0f} s", file=sys.stderr)
    return out


def curve(run_dir: Path) -> list[tuple[int, float]]:
    """(env steps, success rate) of each evaluation during training (metrics.csv)."""
    from motorlab.runs import read_metrics

    return [(int(r["timesteps"]), float(r["eval_success_rate"])) for r in read_metrics(run_dir)
            if r.get("eval_success_rate") == r.get("eval_success_rate") and r.get("eval_success_rate") is not None]


@dataclass(frozen=True)
class FinalEvaluations:
    """An arm's final evaluations, one per seed (each run's summary.json): what sar_study and
    sar_legs both report per arm."""

    seeds: list[int]
    success: list[float]
    returns: list[float]
    episodes: list[int]
    wall_seconds: list[float]

    @classmethod
    def of(cls, summaries: list[dict]) -> FinalEvaluations:
        return cls(seeds=[int(s["seed"]) for s in summaries],
                   success=[float(s["eval_success_rate"]) for s in summaries],
                   returns=[float(s["eval_return_mean"]) for s in summaries],
                   episodes=[int(s["eval_episodes"]) for s in summaries],
                   wall_seconds=[round(float(s["wall_seconds"]), 1) for s in summaries])

    def success_pooled(self) -> dict:
        """The success episodes pooled over the seeds, with their Wilson interval."""
        from motorlab.intervals import pooled_rate

        return pooled_rate([round(r * n) for r, n in zip(self.success, self.episodes)], self.episodes).to_json()


def arm_result(runs: list[Path]) -> dict:
    """One arm over its seeds: success and return per seed, across seeds (the mean, the seeds'
    range, a 95% CI from 5 seeds where it has a width), the episodes pooled (Wilson), the curve's mean."""
    from motorlab.intervals import across_seeds

    final = FinalEvaluations.of([json.loads((r / "summary.json").read_text()) for r in runs])
    curves = [dict(curve(r)) for r in runs]
    steps = sorted(set.intersection(*(set(c) for c in curves))) if curves else []
    return {"seeds": final.seeds, "success_per_seed": final.success,
            "return_per_seed": [round(v, 2) for v in final.returns], "episodes_per_seed": final.episodes,
            "success": across_seeds(final.success).to_json(), "return": across_seeds(final.returns).to_json(),
            "success_pooled": final.success_pooled(), "wall_seconds_per_seed": final.wall_seconds,
            "success_curve_mean": [[t, round(sum(c[t] for c in curves) / len(curves), 3)] for t in steps]}


def learn(args: argparse.Namespace) -> dict:
    """Both arms at equal env steps (see the module's docstring, part 2)."""
    from motorlab.intervals import p_better

    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        jobs = [(arm, seed) for seed in range(args.learn_seeds) for arm in ARMS]  # a slow and a fast one side by side
        with ThreadPoolExecutor(2) as pool:
            done = list(pool.map(lambda job: train_run(args, job[0], job[1], folder), jobs))
        arms = {arm: arm_result([d for (a, _), d in zip(jobs, done) if a == arm]) for arm in ARMS}
    ref, fast = arms["reference_sac"], arms["sar_sac_fast"]
    mean_ref, mean_fast = ref["success"]["value"], fast["success"]["value"]
    low_ref, high_fast = ref["success_pooled"]["ci"][0], fast["success_pooled"]["ci"][1]
    return {
        "env": args.learn_env, "env_steps_per_seed": args.learn_steps, "seeds": args.learn_seeds,
        "episodes_per_seed": args.learn_episodes, "eval_every": args.eval_every,
        "success": 'MyoSuite\'s "solved" at any step of a deterministic episode',
        "arms": {"reference_sac": "sar-sac: one gradient step per env step, 1 env",
                 "sar_sac_fast": "sar-sac-fast: 4 env processes, one gradient step per 25 env steps"},
        **arms,
        "p_fast_better_success": p_better(fast["success_per_seed"], ref["success_per_seed"]).to_json(),
        "p_fast_better_return": p_better(fast["return_per_seed"], ref["return_per_seed"]).to_json(),
        "success_difference_fast_minus_reference": round(mean_fast - mean_ref, 4),
        "target": {"target": "sar_sac_fast's success at equal env steps >= the reference's (mean over seeds)",
                   "met": mean_fast >= mean_ref,
                   # pooled Wilson intervals: is the fast arm's shortfall (or lead) beyond episode noise?
                   "fast_clearly_below": high_fast < low_ref},
    }


if __name__ == "__main__":  # the PPO setting starts env subprocesses, which re-import this file
    main()
