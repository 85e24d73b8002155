"""The SAR locomotion study's cost on this machine: `sar-legs` against its reference settings.

Three parts, in one run, one JSON object:

1. The machine: the legs' env steps/s and SAC's updates/s on one core, against what this project's
   notes measured (machines differ between sessions; the projections below scale with them).
2. Settings (`--chain-steps`, default 6000): the two chains of the study train at the same time,
   as `motorlab run` runs them (play on myoLegWalk-v0 beside RL-E2E on the terrain, each in its own
   process), with each candidate setting: the reference SAC (one gradient step per env step), and
   `sar-sac-fast` with 4, 2 or 1 env processes, 1 or 2 math threads, one gradient step per 25
   or 50 env steps. Env steps per second per
   chain once learning runs (from metrics.csv, evaluation off) give each the hours the full study
   (4M env steps per chain) would take.
3. The study (`--scale`, default 100): `motorlab run sar-legs` with every budget divided by the
   scale (training steps, collected episodes, evaluation interval), once, with the seeds the recipe
   uses (5 per arm). Per arm and seed: success (MyoSuite's "solved" at the final step), return and
   episode length of the final evaluation; per arm the mean over seeds with its interval where the
   seeds allow one (motorlab.intervals) and the success episodes pooled (Wilson); SAR-RL against
   RL-E2E: P(SAR-RL > RL-E2E) with its interval and scipy's one-sided Mann-Whitney U on the
   returns (the science target; at this scale it is recorded, whichever way it goes, and is not the
   full study's). The projected full-size time is each step's measured time times the scale (the
   synergy fit, VAF and curves once), the two chains side by side, as the study runs them on this
   machine; and on a Ray cluster with one machine per seed (steps one after another, one seed's
   time each: the study's time divided by the seeds a step runs at once here is not measured, so
   this uses each seed's own training time). `--scale 0` skips this part. At 1/10 of the budgets
   with 5 seeds a side the part alone takes ~2 h here; at 1/100 about 15 min.

At these budgets no policy learns to walk: the study part measures time and shows the pipeline
and its numbers; the success it reports at a fraction of the budget is not the full study's.

Usage:  .venv/bin/python benchmarks/sar_legs.py [--chain-steps 6000] [--scale 100] [--terrain rough]
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing as mp
import sys
import tempfile
import time
from pathlib import Path

from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path
from sar_robot import arm, compared, science_target  # over seeds, as for the robot (benchmarks/ is on sys.path)
from sar_study import FinalEvaluations, steady_rate  # per-arm evaluations; env steps/s after the warm-up

CHAIN_STEPS = {"play + SAR-RL": 1_500_000 + 2_500_000, "RL-E2E": 4_000_000}
WARM_UP = 1000  # SAC's learning_starts here: env steps before the first update

CANDIDATES = {
    # sar-legs-reference: the reference SAC, one gradient step per env step, one env
    "reference_sac": {"preset": "sar-sac", "torch_threads": 1},
    # sar-legs' choice: the same SAC, one gradient step per 25 env steps, one env in the learner's
    # process, one math thread per chain
    "sar_legs": {"preset": "sar-sac-fast", "torch_threads": 1, "n_envs": 1,
                 "hyperparams": {"train_freq": 25, "gradient_steps": 1}},
    # sar-sac-fast as the hand uses it: 4 env processes (1 gradient step per 25 env steps)
    "fast_4envs_1thread": {"preset": "sar-sac-fast", "torch_threads": 1},
    "fast_4envs_2threads": {"preset": "sar-sac-fast", "torch_threads": 2},
    "fast_2envs_1thread": {"preset": "sar-sac-fast", "torch_threads": 1, "n_envs": 2},
    # 4 env processes, 1 gradient step per 50 env steps: faster, further from the reference
    "fast_4envs_1thread_1_in_50": {"preset": "sar-sac-fast", "torch_threads": 1,
                                   "hyperparams": {"train_freq": 25, "gradient_steps": 2}},
}


# What this project's notes measured on its 2-core machines: the legs through Gymnasium, and one
# update of SAC's [400, 300] networks on a 256 batch, one core each. Machines differ between
# sessions; the projection scales with them.
NOTED = {"legs_env_steps_per_second": 1400, "sac_updates_per_second": 45}


def machine_speed() -> dict:
    """This machine's speed at the study's two costs, alone on one core, against NOTED."""
    import numpy as np
    import torch
    from stable_baselines3 import SAC

    from motorlab.envs import EnvConfig, make_env

    env = make_env(EnvConfig(id="myoLegWalk-v0"), shaped=False)
    env.reset(seed=0)
    env.action_space.seed(0)
    t, steps = time.perf_counter(), 3000
    for _ in range(steps):
        if any(env.step(env.action_space.sample())[2:4]):
            env.reset()
    env_rate = steps / (time.perf_counter() - t)
    torch.set_num_threads(1)
    model = SAC("MlpPolicy", env, policy_kwargs={"net_arch": {"pi": [400, 300], "qf": [400, 300]}}, batch_size=256,
                learning_starts=0, seed=0)
    model.learn(300)
    t = time.perf_counter()
    model.train(gradient_steps=60, batch_size=256)
    update_rate = 60 / (time.perf_counter() - t)
    env.close()
    measured = {"legs_env_steps_per_second": round(env_rate), "sac_updates_per_second": round(update_rate, 1)}
    return {**measured, "noted": NOTED,
            "speed_vs_noted": {k: round(measured[k] / NOTED[k], 2) for k in NOTED},
            "geometric_mean_speed_vs_noted": round(float(np.sqrt(np.prod([measured[k] / NOTED[k] for k in NOTED]))), 2)}


def _train(settings: dict, out: str) -> None:
    from motorlab.kinds.train import TRAIN
    from motorlab.rl.config import resolve
    from motorlab.rl.train import train

    train(resolve(settings), Path(out), kind=TRAIN.name)


def both_chains(name: str, settings: dict, steps: int, terrain: str, tmp: Path) -> dict:
    """Play and RL-E2E trained at once with `settings`, as the study's two chains."""
    common = {**settings, "timesteps": steps, "eval_every": 10**9, "solve_episodes": 1, "progress": False,
              "checkpoint_every": 0, "success": "final",
              "hyperparams": {**settings.get("hyperparams", {}), "learning_starts": WARM_UP}}
    envs = {"play + SAR-RL": "myoLegWalk-v0", "RL-E2E": terrain}
    spawn = mp.get_context("spawn")  # as `motorlab run` does: each chain a fresh process
    procs = {chain: spawn.Process(target=_train, args=({**common, "env": env_id}, str(tmp / name / chain)))
             for chain, env_id in envs.items()}
    for p in procs.values():
        p.start()
    for chain, p in procs.items():
        p.join()
        if p.exitcode != 0:
            raise SystemExit(f"{name} ({chain}) failed with exit code {p.exitcode}")
    rates = {chain: steady_rate(tmp / name / chain, WARM_UP) for chain in envs}
    hours = max(CHAIN_STEPS[c] / rates[c] for c in envs) / 3600
    print(f"{name}: {', '.join(f'{c} {r:.0f}' for c, r in rates.items())} env steps/s -> {hours:.1f} h",
          file=sys.stderr)
    return {"env_steps_per_second": {c: round(r, 1) for c, r in rates.items()},
            "projected_training_hours": round(hours, 2)}


def scaled_study(scale: int, terrain: str, out: Path) -> dict:
    """`sar-legs` with every budget divided by `scale`; per-arm results and the projected full time."""
    from motorlab.intervals import p_better
    from motorlab.recipes import load_recipe
    from motorlab.runs import read_json
    from motorlab.studies import run_study

    full = {s.name: s.fields for s in load_recipe("sar-legs").steps}
    given = {"terrain": terrain, "eval_every": full["play"]["eval_every"] // scale}
    for step in ("play", "sar-rl", "rl-e2e"):
        given[f"{step}.timesteps"] = full[step]["timesteps"] // scale
    for field in ("episodes", "preview"):
        given[f"collect.{field}"] = max(1, round(full["collect"][field] / scale))
    recipe = load_recipe("sar-legs", given)
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(sys.stderr):  # the study's progress and table; stdout is the JSON
        seconds = run_study(recipe, out)["step_seconds"]
    wall = time.perf_counter() - t0
    arms, per_seed_seconds = {}, {}
    for step in ("sar-rl", "rl-e2e"):
        runs = sorted((out / step).glob("seed*/summary.json")) or [out / step / "summary.json"]
        summaries = [read_json(p) for p in runs]
        arms[step] = per_arm(summaries)
        per_seed_seconds[step] = max(s["wall_seconds"] for s in summaries)
    versus = compared(arms["sar-rl"]["return"], arms["rl-e2e"]["return"])
    return {"scale": scale, "recipe_given": given, "wall_seconds": round(wall, 1), "step_seconds": seconds,
            "slowest_seed_seconds": per_seed_seconds, "arms": arms, "sar_rl_vs_rl_e2e_return": versus,
            "p_sar_better_success": p_better(arms["sar-rl"]["success"]["per_seed"],
                                             arms["rl-e2e"]["success"]["per_seed"]).to_json(),
            "science_target": science_target(arms["sar-rl"]["return"], arms["rl-e2e"]["return"])}


def per_arm(summaries: list[dict]) -> dict:
    """One arm's final evaluations over its seeds: success and return per seed and across seeds,
    the success episodes pooled over the seeds with their Wilson interval."""
    final = FinalEvaluations.of(summaries)
    return {"env": summaries[0]["env_id"], "seeds": final.seeds,
            "timesteps_per_seed": summaries[0]["timesteps"], "success_by": summaries[0].get("success_by"),
            "success": arm(final.success), "return": arm(final.returns), "success_pooled": final.success_pooled(),
            "episode_length_mean_per_seed": [round(float(s["eval_episode_length_mean"]), 1) for s in summaries],
            "evaluation_episodes_per_seed": final.episodes, "wall_seconds_per_seed": final.wall_seconds}


def project_cluster(study: dict) -> float:
    """Hours the full study would take on a Ray cluster with a machine per seed: its steps one after
    another (--backend ray), each as long as its slowest seed here times the scale; VAF, fit and
    curves once."""
    s, k = study["step_seconds"], study["scale"]
    slowest = study["slowest_seed_seconds"]
    return (sum(s.get(n, 0) * k for n in ("play", "collect")) + sum(s.get(n, 0) for n in ("vaf", "fit", "curves"))
            + (slowest["sar-rl"] + slowest["rl-e2e"]) * k) / 3600


def project(study: dict) -> float:
    """Hours the full study would take: scaled steps' times times the scale, the chains side by side."""
    s, k = study["step_seconds"], study["scale"]
    known = s
    chain_a = sum(known.get(n, 0) * k for n in ("play", "collect", "sar-rl")) + sum(known.get(n, 0) for n in ("vaf", "fit"))
    chain_b = known.get("rl-e2e", 0) * k
    rest = known.get("curves", 0)
    return (max(chain_a, chain_b) + rest) / 3600


def terrains() -> dict[str, str]:
    """The terrain input's choices in the sar-legs recipe: name -> env id."""
    import tomllib

    from motorlab.recipes import find_recipe

    return tomllib.loads(find_recipe("sar-legs").read_text())["inputs"]["terrain"]["choices"]


def main() -> None:
    terrain_ids = terrains()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--chain-steps", type=int, default=6000, help="env steps per chain per setting (0: skip)")
    parser.add_argument("--only", nargs="*", default=None, help="candidate settings to measure (default: all)")
    parser.add_argument("--scale", type=int, default=100, help="run sar-legs with budgets / SCALE (0: skip)")
    parser.add_argument("--terrain", choices=sorted(terrain_ids), default="rough")
    parser.add_argument("--keep", type=Path, default=None, help="keep the runs in this folder")
    args = parser.parse_args()
    recorder = Recorder("sar_legs")  # the git state and load, read as the run starts
    out: dict = {"benchmark": "sar_legs", "terrain": terrain_ids[args.terrain], "chain_env_steps": CHAIN_STEPS}
    out["machine"] = machine_speed()  # kept beside the recorder's cpu, cores and load
    print(f"machine: {out['machine']['speed_vs_noted']} of the noted speeds", file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = args.keep or Path(tmp_name)
        if args.chain_steps:
            out["chain_steps_per_setting"] = args.chain_steps
            out["settings"] = {name: both_chains(name, settings, args.chain_steps, terrain_ids[args.terrain], tmp)
                               for name, settings in CANDIDATES.items() if args.only is None or name in args.only}
        if args.scale:
            study = scaled_study(args.scale, args.terrain, tmp / "study")
            study["projected_full_hours"] = round(project(study), 2)
            study["projected_full_hours_ray_cluster_one_machine_per_seed"] = round(project_cluster(study), 2)
            out["study"] = study
    settings = out.get("settings", {})
    if "reference_sac" in settings and "sar_legs" in settings:
        ref = settings["reference_sac"]["projected_training_hours"]
        fast = settings["sar_legs"]["projected_training_hours"]
        out["reference_over_sar_legs_hours"] = round(ref / fast, 1)
    out["target"] = "the full sar-legs study <= 3 h on this machine"
    if "study" in out:
        hours = out["study"]["projected_full_hours"]
        out["target_met"] = hours <= 3.0
        out["targets"] = {"wall": {"target": out["target"], "hours": hours, "met": hours <= 3.0},
                          "science": {**out["study"]["science_target"],
                                      "note": f"at 1/{args.scale} of the budgets: not the full study's claim"}}
        # roughly, on a machine at the noted speeds (env stepping and updates are most of the time)
        out["study"]["projected_full_hours_at_noted_speeds"] = round(
            hours * out["machine"]["geometric_mean_speed_vs_noted"], 2)
    recorder.record(out)


if __name__ == "__main__":  # spawned chains and env subprocesses re-import this file
    main()
