"""The `mpc` step kind: model-predictive control on a learned forward model."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field
from rich.console import Console

from motorlab.envs import EnvConfig, check_env_id, make_env
from motorlab.report.results import Metric
from motorlab.runs import MetricsWriter, atomic_write_npz
from motorlab.settings import Settings, Summary
from motorlab.stepkind import Ref, StepKind

PLAN = ("horizon", "population", "iterations", "elites")


class MpcSettings(Settings):
    # Tuned on Reacher-v5 (benchmarks/mpc.py): ~4 ms per control step on one core, return ~-3.6.
    # The horizon matters most (10 steps: ~-4.6); population x iterations buys precision at ~0.6 us per row.
    env: str = Field(description="Env id the model was fit on, e.g. Reacher-v5")
    model: str = Field(description="A model folder from `motorlab dynamics fit`")
    episodes: int = Field(50, gt=0, description="Episodes to control")
    horizon: int = Field(15, gt=0, description="Planning horizon in control steps")
    population: int = Field(100, gt=0, description="Action sequences per CEM iteration")
    iterations: int = Field(5, gt=0, description="CEM iterations per control step")
    elites: int = Field(10, gt=0, description="Best sequences the Gaussian is refit to")
    optimizer: Literal["cem", "evotorch"] = Field("cem", description="cem (motorlab's, batched) or evotorch "
                                                  "(EvoTorch's CEM)")
    parallel: int = Field(1, gt=0, description="Episodes run side by side, planned in one batched call")
    video: bool = Field(False, description="Also render the first episode to videos/episode_0.mp4")
    seed: int = Field(0, ge=0, description="Random seed (env resets and the planner)")

    def plan(self) -> dict[str, int]:
        """The planner's settings."""
        return {k: getattr(self, k) for k in PLAN}


class MpcSummary(Summary):
    env_id: str
    episodes: int
    return_mean: float
    return_std: float
    return_min: float
    final_distance_mean: float
    final_distance_median: float
    plan_ms_median: float
    plan_call_ms_median: float
    parallel: int
    optimizer: str
    horizon: int
    population: int
    iterations: int
    elites: int
    wall_seconds: float
    numerical_faults: int  # and "video", the first episode's MP4, when one was asked for


class MpcKind(StepKind[MpcSettings, MpcSummary]):
    """Model-predictive control: CEM on a learned forward model, maximizing the env's own reward.

    summary.json: return_mean, return_std, final_distance_mean (metres), plan_ms_median (per env per control
    step); episodes.npz, metrics.csv (one row per episode), plots/distance.png."""

    name = "mpc"
    what = "MPC ({optimizer}) on {model} · {env}"
    headline_keys = ("return_mean", "return_std", "return_min", "final_distance_mean", "plan_ms_median", "episodes",
                     "wall_seconds")
    refs = (Ref("model", ("model",)),)
    metrics = (Metric("return_mean", "return", spread="return_std"),
               Metric("return_min", "min return"),
               Metric("final_distance_mean", "final distance", "mm", scale=1000),
               Metric("plan_ms_median", "planning time per step", "ms"),
               Metric("episodes", "episodes", "count", setup=True),
               Metric("wall_seconds", "wall time", "s", setup=True))
    findings = ("return_mean", "final_distance_mean", "plan_ms_median")
    key_figures = ("plots/distance.png",)

    def check(self, settings: MpcSettings) -> None:
        check_env_id(settings.env)

    def run(self, settings: MpcSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> MpcSummary:
        from motorlab.control.mpc_episodes import build_policy, record_video, run_episodes
        from motorlab.report.dynamics_plots import distance_over_time

        s = settings
        env = make_env(EnvConfig(id=s.env), shaped=False)
        policy = build_policy(env, s.env, Path(s.model), s.optimizer, s.seed, **s.plan())
        dt = float(getattr(env.unwrapped, "dt", 0.0)) or None
        env.close()
        parallel = min(s.parallel, s.episodes)
        run_dir = self.start(out)
        start = time.perf_counter()
        returns, distances, call_ms, per_env_ms, fault_log = run_episodes(s.env, policy, s.episodes, s.seed,
                                                                           parallel, progress)
        wall = time.perf_counter() - start
        final = distances[:, -1]
        metrics = MetricsWriter(run_dir / "metrics.csv", ["episode", "return", "final_distance"])
        for i, (r, d) in enumerate(zip(returns, final, strict=True)):
            metrics.write({"episode": i, "return": r, "final_distance": d})
        metrics.close()
        atomic_write_npz(run_dir / "episodes.npz", returns=returns, distances=distances, plan_ms=call_ms)
        if np.isfinite(distances).all():
            distance_over_time(distances, run_dir / "plots" / "distance.png",
                               f"{s.env}: MPC ({s.optimizer}, horizon {s.horizon}, {s.population} x {s.iterations})",
                               dt=dt)
        video = {"video": str(record_video(s.env, policy, run_dir / "videos" / "episode_0.mp4", s.seed))
                 } if s.video else {}
        summary = MpcSummary(env_id=s.env, episodes=s.episodes, return_mean=float(returns.mean()),
                             return_std=float(returns.std()), return_min=float(returns.min()),
                             final_distance_mean=float(final.mean()), final_distance_median=float(np.median(final)),
                             plan_ms_median=float(np.median(per_env_ms)), plan_call_ms_median=float(np.median(call_ms)),
                             parallel=parallel, optimizer=s.optimizer, **s.plan(), wall_seconds=wall,
                             numerical_faults=len(fault_log), **video)
        return self.finish(run_dir, settings, summary, fault_log)


MPC = MpcKind()
