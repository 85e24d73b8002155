"""One env's planning latency at the model-based loop's defaults, for every env of benchmarks/mbrl.py.

    .venv/bin/python benchmarks/plan_latency.py [ENV ...] [--steps 40]

What a user's `motorlab mpc` (or the loop's collection) waits per control step for ONE env: the
loop's defaults resolved for the env (MbrlSettings: motorlab's, and the env catalogue's planner and
model settings: horizon, population, iterations, members, TS particles, termination draws, the
model's hidden layers), planning on one torch thread. The model is the loop's architecture fitted
for 2 epochs on 4 random episodes: the time of a planning call does not depend on how well the
weights predict (the same ops on the same shapes), so no learning is needed to time it.
Per env: the median and 90th percentile of `MPCPolicy.act` over --steps control steps of one
episode (after 3 warm-up calls), against the issue's target of 50 ms per control step.

The peer here is the target itself, not another planner: benchmarks/mbrl.py compares the loop
with SAC, and records each loop seed's collection time per step (an upper bound of this figure).

Output: one JSON object on stdout, also written to benchmarks/results/plan_latency.json, with the
resolved settings per env and, by provenance.Recorder, the date, the command line, the git commit,
versions, the CPU and the load average.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time

from mbrl import ENVS  # benchmarks/ is the script's folder
from provenance import Recorder

TARGET_MS = 50.0
WARM_UP = 3


def latency(name: str, steps: int, overrides: dict[str, str]) -> dict:
    import numpy as np
    import torch

    from motorlab.dynamics.collection import collect_transitions
    from motorlab.dynamics.train import fit_model
    from motorlab.envs import make_env
    from motorlab.kinds.planning import MbrlSettings
    from motorlab.planning.mbrl import env_config
    from motorlab.planning.mpc_episodes import build_policy

    torch.set_num_threads(1)
    spec = ENVS[name]
    settings = MbrlSettings(env=spec["id"], reward=spec["reward"], device="cpu", **overrides)
    plan = settings.loop_plan()
    cfg = env_config(plan)
    data = collect_transitions(cfg, 4, "random", workers=1, seed=0, state=plan.state, progress=False)
    model, _ = fit_model(data, **{**plan.fit, "epochs": 2}, progress=False)
    env = make_env(cfg, shaped=False)
    try:
        policy = build_policy(env, cfg, model, plan.optimizer, 0, **plan.scoring, **plan.plan)
        policy.reset(1)
        obs, _ = env.reset(seed=0)
        times = []
        for t in range(WARM_UP + steps):
            start = time.perf_counter()
            action = policy.act(np.asarray(obs)[None])[0]
            if t >= WARM_UP:
                times.append(1000 * (time.perf_counter() - start))
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                obs, _ = env.reset(seed=t)
                policy.reset(1)
    finally:
        env.close()
    ms = statistics.median(times)
    return {"env_id": spec["id"], "ms_median": round(ms, 2),
            "ms_p90": round(float(np.percentile(times, 90)), 2), "steps": len(times),
            "met": ms <= TARGET_MS,
            "settings": {**plan.plan, **{k: v for k, v in plan.scoring.items() if k != "device"},
                         "hidden": list(plan.fit["hidden"]), "nonlinearity": plan.fit["nonlinearity"],
                         "ensemble": plan.fit["ensemble"],
                         "probabilistic": plan.fit["probabilistic"], "state": plan.state}}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    parser.add_argument("envs", nargs="*", default=[], metavar="ENV",
                        help=f"envs to time (default: all of {', '.join(ENVS)})")
    parser.add_argument("--steps", type=int, default=40, help="timed control steps per env")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a loop setting (an MbrlSettings field) instead of its default, for experiments; "
                             "the JSON records it (e.g. --set horizon=25 --set 'hidden=[128,128]')")
    args = parser.parse_args(argv)
    unknown = [e for e in args.envs if e not in ENVS]
    if unknown:
        parser.error(f"unknown env {unknown[0]!r}: give any of {', '.join(ENVS)}")
    overrides = {k: json.loads(v) if v[:1] in "[{" else v for k, v in (s.split("=", 1) for s in args.set)}
    recorder = Recorder("plan_latency")  # the git state and load now: what ran is the code loaded as it starts
    if argv is not None:
        recorder.argv = list(argv)  # called from Python: these were its arguments
    per_env = {}
    for name in args.envs or list(ENVS):
        per_env[name] = latency(name, args.steps, overrides)
        print(f"[plan-latency] {name}: {per_env[name]['ms_median']:.1f} ms median", file=sys.stderr, flush=True)
    recorder.record({"target_ms": TARGET_MS,
                     "basis": "one env, one torch thread, MPCPolicy.act per control step at the loop's defaults",
                     "set": overrides, "envs": per_env, "all_met": all(r["met"] for r in per_env.values())})


if __name__ == "__main__":
    main()
