"""Throughput of SAR-RL training: motorlab's candidate settings vs the reference SAC.

Trains in synergy space on myoHandReorient100-v0 (phi = 0.66, the SAR published with
MyoSuite, imported with --trust from ../shared/data) for a short budget with each
setting, in this one process, and reports env steps per second once learning runs (timed
from metrics.csv after the warm-up; evaluation switched off) and the hours the full sar-hand study (1M play + 1.5M SAR-RL
+ 2.5M RL-E2E = 5M env steps) would take at that rate.

This measures speed only. How much each setting learns per env step needs long runs
(the reference makes ~40 env steps/s here); the evidence is in the issue notes.

Usage:  .venv/bin/python benchmarks/sar_study.py [--steps 3000]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
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
    from motorlab.rl.config import resolve
    from motorlab.rl.train import train
    from motorlab.synergies import import_sklearn

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4000, help="env steps per setting (the first 1000-2048 warm up)")
    args = parser.parse_args()
    recorder = Recorder("sar_study")  # the git state and load, read as the run starts
    out = {"benchmark": "sar_study", "env": "myoHandReorient100-v0", "phi": 0.66, "steps_per_setting": args.steps,
           "study_env_steps": STUDY_STEPS, "settings": {}}
    with tempfile.TemporaryDirectory() as tmp:
        sar = Path(tmp) / "sar.npz"
        import_sklearn(PUBLISHED, trust=True, out=sar)
        for name, settings in CANDIDATES.items():
            cfg = resolve({**settings, "env": {"id": "myoHandReorient100-v0", "sar": str(sar), "phi": 0.66},
                           "timesteps": args.steps, "eval_every": 10**9, "progress": False, "solve_episodes": 1})
            s = train(cfg, Path(tmp) / name)
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
    recorder.record(out)


if __name__ == "__main__":  # the PPO setting starts env subprocesses, which re-import this file
    main()
