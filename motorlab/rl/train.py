"""`motorlab train`: one training run, one run folder.

    run_dir/config.toml        resolved settings (preset applied)
    run_dir/metrics.csv        training episodes and evaluations
    run_dir/tensorboard/       SB3's scalars and motorlab's eval/ scalars
    run_dir/policy.json (+ policy.safetensors)   the policy, pickle-free
    run_dir/model.zip          SB3 model for continuing training (SB3 algorithms)
    run_dir/summary.json       headline numbers
    run_dir/plots/learning_curve.png
    run_dir/environment.json   Python, machine and library versions
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from motorlab import algos
from motorlab.envs import max_return
from motorlab.errors import MotorlabError
from motorlab.evaluation import success_by, success_mode
from motorlab.policies import load_policy_files
from motorlab.report.plots import plot_learning_curve
from motorlab.rl.config import TrainConfig
from motorlab.rl.envcheck import check_train_env
from motorlab.rl.monitor import EVAL_SEED_OFFSET, TrainingMonitor, monitor_record
from motorlab.runs import run_path, write_config


def train(cfg: TrainConfig, out: Path | None = None, resume: bool = False, *,
          start: Callable[[Path], Path]) -> dict[str, Any]:
    """Train one policy as `cfg` says into its run folder; the train kind (`motorlab.kinds.train.TRAIN.run`)
    ends the folder with the shared `finish` (config.toml, results.json, summary.json).

    Args:
        start: opens the run folder once the settings are known good (`StepKind.start`: made,
            marked as the train kind's, so that `motorlab train --resume` continues it, locked, tracked).
        resume: continue the run in `out` from its last checkpoint (SB3 algorithms; an LQR
            run, or one killed before its first checkpoint, starts over).

    Returns:
        The summary, with `run_dir`: `steps_to_success` (int, or None when the budget ran out
        first), `wall_seconds`, `timesteps`, final evaluation.

    Raises:
        MotorlabError: bad env id, delay, reward, an algorithm that does not fit the env's spaces,
            --her where it cannot relabel, or no solve target for --until-solved.
    """
    # env id, delay, reward, the algorithm against the env's spaces, --her: before anything is written
    check_train_env(cfg)
    solve_return = cfg.solve_return if cfg.solve_return is not None else max_return(cfg.env.id)
    if cfg.until_solved and solve_return is None:
        raise MotorlabError(f"{cfg.env.id} has no known maximum return; give --solve-return for --until-solved.")

    run_dir = run_path(out, f"train-{cfg.algo}")
    t0 = time.perf_counter()
    model = None
    record = None
    algo = algos.get(cfg.algo)
    if algo.sb3:  # torch and SB3 are imported here: an LQR run (NumPy, SciPy) starts without them
        import torch

        from motorlab.rl.checkpoint import has_checkpoint, load_checkpoint
        from motorlab.rl.sb3 import build_model

        torch.set_num_threads(cfg.torch_threads)
        model = build_model(cfg, run_dir)  # SB3 checks its settings here, before the folder is touched
        if resume and has_checkpoint(run_dir):
            record = load_checkpoint(run_dir, model)
    start(run_dir)  # a tracked run (--track) starts now, before the first scalar
    if record is None:
        shutil.rmtree(run_dir / "checkpoint", ignore_errors=True)  # another run's, not to be resumed into this one
    write_config(run_dir, cfg.model_dump())
    monitor = TrainingMonitor(cfg, run_dir, solve_return, resume=record)
    try:
        if model is None:
            steps = algo.learn(cfg, run_dir, monitor)  # an algorithm that trains itself (LQR)
        else:
            from motorlab.rl.sb3 import train_sb3

            steps = train_sb3(cfg, model, run_dir, monitor)
        wall = time.perf_counter() - t0 + (monitor_record(record)["wall"] if record else 0.0)
        # Reload from disk, so the reported numbers are those of the saved files.
        rollouts = monitor.evaluator.run(load_policy_files(run_dir))
        final = rollouts.summary()
    finally:
        monitor.close()
    summary = {
        "env_id": cfg.env.id,
        "algo": cfg.algo,
        "preset": cfg.preset,
        "seed": cfg.seed,
        "delay": cfg.env.delay,
        "history": cfg.env.history,
        "timesteps": steps,
        "budget": cfg.timesteps,
        "until_solved": cfg.until_solved,
        "solve_return": solve_return,
        "steps_to_success": monitor.steps_to_success,
        "solved": monitor.steps_to_success is not None,
        "wall_seconds": round(wall, 3),
        # what ended training: the env-step budget, --minutes of training, or --until-solved
        "stopped_by": ("solved" if cfg.until_solved and monitor.steps_to_success is not None
                       else "minutes" if monitor.out_of_time else "timesteps"),
        "minutes": cfg.minutes,
        "train_seconds": round(monitor.train_seconds(), 3),
        "evaluations": monitor.evaluations,
        "train_episodes": monitor.episodes,
        "train_success_rate_last100": monitor.success_rate(),
        "success_mode": success_mode(cfg.env),
        "success_by": success_by(cfg.env, rollouts.success_key),
        "numerical_faults": monitor.faults,
        "resumed_from": record["steps"] if record else None,
        "eval_seed": cfg.seed + EVAL_SEED_OFFSET,
        **{f"eval_{k}": v for k, v in final.items() if k != "episode_lengths"},
        "eval_episode_lengths": final["episode_lengths"],
    }
    summary["run_dir"] = str(run_dir)
    return summary


def finished(run_dir: Path) -> None:
    """After the run's summary.json: the checkpoint goes (nothing is left to resume; replay buffers are big)
    and the learning curve is drawn (people would rather look at it than read metrics.csv)."""
    shutil.rmtree(run_dir / "checkpoint", ignore_errors=True)
    plot_learning_curve(run_dir)
