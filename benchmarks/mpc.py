"""The model-based pipeline on Reacher-v5: motorlab's collect -> fit -> batched-CEM MPC vs the reference planner.

motorlab: `motorlab run reacher`'s steps in one process, timed end to end: collect 20,000
random episodes, fit the forward model (the recipe's: [64, 64] units, else defaults), 50 MPC episodes on Reacher-v5 with the
default planner (one episode at a time, `--parallel 1`). Reports the env's mean return,
the mean final fingertip-to-target distance and the median planning time per control step.

Reference (the notebook's planner) on the same model: EvoTorch CEM, a fresh search each
control step, population 250, 20 iterations, horizon 4, cost = the final fingertip-to-
target distance, over 20 episodes (it is ~30 ms a step).

Usage:  .venv/bin/python benchmarks/mpc.py [--episodes 50] [--reference-episodes 20]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import logging
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

from motorlab.dynamics.layouts.reacher import REACHER
from motorlab.dynamics.model import load_model
from motorlab.dynamics.planner_rewards import reacher_distance
from motorlab.envs import EnvConfig, make_env
from motorlab.kinds.dynamics import DYNAMICS_COLLECT, DYNAMICS_FIT
from motorlab.kinds.planning import MpcSettings
from motorlab.planning.mpc_episodes import build_policy, run_episodes

TARGETS = {"plan_ms_median": 5.0, "return_mean": -4.0, "final_distance_mean": 0.010, "pipeline_seconds": 180.0}
# The time targets were set on a machine where the reference planner took 29.7 ms a step
# (issue 4). Machines here differ by several times in speed from session to session, so
# the time targets are also given scaled by how long the reference planner takes on this
# one, in this same run; the unscaled verdict stays beside it.
ISSUE_REFERENCE_PLAN_MS = 29.7
TIME_TARGETS = ("plan_ms_median", "pipeline_seconds")


class ReferencePlanner:
    """The notebook's MPC: EvoTorch CEM from scratch each step, minimizing the final distance."""

    def __init__(self, model, horizon: int = 4, population: int = 250, iterations: int = 20):
        import evotorch  # noqa: F401  (sets its logger to INFO on import; quiet it after)

        self.model, self.horizon, self.population, self.iterations = model, horizon, population, iterations
        logging.getLogger("evotorch").setLevel(logging.WARNING)

    def reset(self, n: int) -> None:
        pass

    @torch.no_grad()
    def act(self, obs: np.ndarray) -> np.ndarray:
        from evotorch import Problem
        from evotorch.algorithms import CEM

        state = torch.as_tensor(REACHER.state(obs), dtype=torch.float32)
        goal = torch.as_tensor(REACHER.goal(obs), dtype=torch.float32)

        def cost(x: torch.Tensor) -> torch.Tensor:
            seqs = x.reshape(len(x), self.horizon, 2).clamp(-1, 1)
            s = state.expand(len(x), -1)
            for t in range(self.horizon):
                s = self.model.predict(s, seqs[:, t])
            return reacher_distance(s, goal)

        problem = Problem("min", cost, solution_length=2 * self.horizon, vectorized=True, dtype=torch.float32)
        searcher = CEM(problem, popsize=self.population, parenthood_ratio=0.1, stdev_init=0.5,
                       center_init=torch.zeros(2 * self.horizon))
        for _ in range(self.iterations):
            searcher.step()
        return searcher.status["center"][:2].clamp(-1, 1).numpy()[None]


def reference_episodes(model, episodes: int, seed: int) -> dict[str, float]:
    env = make_env(EnvConfig(id="Reacher-v5"), shaped=False)
    planner = ReferencePlanner(model)
    returns, finals, ms = [], [], []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        ret, done = 0.0, False
        while not done:
            start = time.perf_counter()
            action = planner.act(obs[None])[0]
            ms.append((time.perf_counter() - start) * 1000)
            obs, r, terminated, truncated, _ = env.step(action)
            ret += r
            done = terminated or truncated
        returns.append(ret)
        finals.append(float(np.linalg.norm(obs[8:10])))
    return {"return_mean": float(np.mean(returns)), "return_std": float(np.std(returns)),
            "final_distance_mean": float(np.mean(finals)), "plan_ms_median": float(np.median(ms)),
            "episodes": episodes}


# the reacher recipe's fit settings besides its defaults (motorlab/recipes/reacher.toml): what it times
RECIPE_FIT = {"hidden": [64, 64]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--collect-episodes", type=int, default=20000)
    parser.add_argument("--episodes", type=int, default=50, help="motorlab MPC episodes")
    parser.add_argument("--reference-episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    recorder = Recorder("mpc")  # the git state and load, read as the run starts

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        start = time.perf_counter()
        collected = DYNAMICS_COLLECT.run(DYNAMICS_COLLECT.make(env="Reacher-v5", episodes=args.collect_episodes,
                                                               seed=args.seed), tmp / "data", progress=False)
        fitted = DYNAMICS_FIT.run(DYNAMICS_FIT.make(transitions=str(tmp / "data"), seed=args.seed, **RECIPE_FIT),
                                  tmp / "model", progress=False)
        env = make_env(EnvConfig(id="Reacher-v5"), shaped=False)
        plan = MpcSettings(env="Reacher-v5", model=str(tmp / "model")).plan()  # motorlab mpc's defaults
        policy = build_policy(env, "Reacher-v5", tmp / "model", seed=args.seed, **plan)
        result = run_episodes("Reacher-v5", policy, args.episodes, 10_000 + args.seed, 1, progress=False)
        returns, distances, per_env_ms = result.returns, result.distances, result.per_env_ms
        pipeline = time.perf_counter() - start
        ours = {"return_mean": float(returns.mean()), "return_std": float(returns.std()),
                "final_distance_mean": float(distances[:, -1].mean()), "plan_ms_median": float(np.median(per_env_ms)),
                "episodes": args.episodes, "pipeline_seconds": pipeline,
                "collect_seconds": collected.collect_seconds, "fit_seconds": fitted.wall_seconds,
                "valid_mse": fitted.valid_mse,
                "planner": {k: getattr(policy.planner, k) for k in ("horizon", "population", "iterations", "elites")}}
        reference = reference_episodes(load_model(tmp / "model"), args.reference_episodes, 10_000 + args.seed)
    slowdown = reference["plan_ms_median"] / ISSUE_REFERENCE_PLAN_MS
    scaled = {k: v * slowdown if k in TIME_TARGETS else v for k, v in TARGETS.items()}

    def meets(targets: dict[str, float]) -> bool:
        return all(ours[k] >= v if k == "return_mean" else ours[k] <= v for k, v in targets.items())

    recorder.record({
        "benchmark": "mpc", "env_id": "Reacher-v5", "cpus": os.cpu_count(),
        "machine": platform.processor() or platform.machine(), "motorlab": ours, "reference": reference,
        "plan_speedup": reference["plan_ms_median"] / ours["plan_ms_median"],
        "return_gain": ours["return_mean"] - reference["return_mean"], "targets": TARGETS, "meets_targets": meets(TARGETS),
        "machine_slowdown_vs_issue": slowdown, "targets_scaled_to_this_machine": scaled,
        "meets_scaled_targets": meets(scaled),
    })


if __name__ == "__main__":
    main()
