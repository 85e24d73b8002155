"""`motorlab synergies collect`: muscle activations from a trained policy's good episodes.

Preview episodes set a return threshold at the P-th percentile; then episodes are
run until N of them reach it, and their per-step muscle activations (MuJoCo's
`data.act`, read after each step from the unwrapped env) are kept. Episodes run
in a process pool, each from its own seed, so the result does not depend on the
number of workers.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import Progress

from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.evaluate import EpisodeSuccess, success_mode, trained_env_settings
from motorlab.faults import fault_line, fault_of, write_faults_log
from motorlab.runs import atomic_write_npz, prepare_run_dir, require_run_dir, write_config, write_summary

ACTIVATIONS = "activations.npz"


@dataclass
class Episode:
    seed: int
    ret: float
    length: int
    solved: bool
    activations: np.ndarray  # (length, n_muscles)
    fault: str | None = None  # the numerical fault that ended it; such episodes are never kept


def muscle_activations(env) -> np.ndarray:
    """The current muscle activations of a MuJoCo env (data.act)."""
    base = env.unwrapped
    data = getattr(base, "mj_data", None) or getattr(base, "data", None)
    act = getattr(data, "act", None)
    if act is None or act.size == 0:
        spec = env.spec.id if env.spec else type(base).__name__
        raise MotorlabError(f"{spec} has no muscle activations (MuJoCo data.act is empty); synergies need a muscle model.")
    return np.array(act, dtype=np.float32)


# ---- one worker: its own env and policy, loaded once --------------------------------

_worker: dict[str, Any] = {}


def _init_worker(run_dir: str, env_cfg: dict, deterministic: bool) -> None:
    import torch

    from motorlab.policies import load_policy_files

    torch.set_num_threads(1)
    cfg = EnvConfig.model_validate(env_cfg)
    _worker["env"] = make_env(cfg, shaped=False)
    policy = load_policy_files(Path(run_dir))
    if hasattr(policy, "deterministic"):
        policy.deterministic = deterministic
    _worker["policy"] = policy
    from motorlab.envs import max_return

    _worker["target"] = max_return(cfg.id)
    _worker["success"] = success_mode(cfg)


def _run_episode(seed: int) -> Episode:
    import torch

    env, policy = _worker["env"], _worker["policy"]
    torch.manual_seed(seed)  # stochastic actions repeat for the same seed
    obs, _ = env.reset(seed=seed)
    policy.reset(1)
    outcome = EpisodeSuccess(1, _worker["target"], _worker["success"])
    acts, ret, done = [], 0.0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs[None])[0])
        acts.append(muscle_activations(env))
        outcome.step(0, info)
        ret += float(reward)
        done = terminated or truncated
    return Episode(seed, ret, len(acts), bool(outcome.end(0, ret)), np.stack(acts), fault_of(info))


def _episodes(seeds: list[int], workers: int, init_args: tuple):
    """Yield episodes for `seeds` in order, from a pool of `workers` processes (in-process for 1)."""
    if workers <= 1:
        _init_worker(*init_args)
        for s in seeds:
            yield _run_episode(s)
        return
    # spawn: a fresh interpreter per worker is safe with torch and MuJoCo state
    with mp.get_context("spawn").Pool(workers, initializer=_init_worker, initargs=init_args) as pool:
        yield from pool.imap(_run_episode, seeds)


def collect(run_dir: Path, episodes: int, percentile: float = 80.0, preview: int = 20, seed: int = 0,
            deterministic: bool = False, workers: int | None = None, max_episodes: int | None = None,
            out: Path | None = None, progress: bool = True) -> dict[str, Any]:
    """Collect muscle activations of `episodes` episodes at or above the preview's percentile.

    Args:
        run_dir: a finished training run (its policy and env are used).
        episodes: episodes to keep (N).
        percentile: P; the threshold is the P-th percentile of the preview returns.
        preview: episodes run first to set the threshold (M).
        deterministic: act with the policy's mean action instead of sampling.
        workers: processes (default: all cores).
        max_episodes: give up after this many episodes past the preview (default 20 N).

    Returns:
        The summary; `activations.npz` in the output folder holds `activations` (S, n_muscles),
        `episode` (S,) index into the kept episodes, `returns` (N,), `threshold`,
        `preview_returns` (M,), `seeds` (N,) and `metadata` (JSON string).

    Raises:
        MotorlabError: bad counts, an env without muscles, or no episode reaching the threshold.
    """
    if episodes <= 0 or preview <= 0:
        raise MotorlabError(f"--episodes and --preview must be positive, got {episodes} and {preview}.")
    if not 0.0 <= percentile <= 100.0:
        raise MotorlabError(f"--percentile must be between 0 and 100, got {percentile}.")
    run_dir = require_run_dir(Path(run_dir))
    cfg = EnvConfig.model_validate(trained_env_settings(run_dir))
    probe = make_env(cfg)
    muscle_activations(probe)  # fail early for an env without muscles
    probe.close()
    workers = workers or os.cpu_count() or 1
    max_episodes = max_episodes or 20 * episodes
    init_args = (str(run_dir), cfg.model_dump(), deterministic)

    kept: list[Episode] = []
    fault_log: list[str] = []  # faulted episodes neither set the threshold nor are kept: their activations diverged
    with Progress(disable=not progress, transient=False) as bar:
        task = bar.add_task("preview episodes", total=preview)
        preview_returns = []
        for ep in _episodes([seed + i for i in range(preview)], workers, init_args):
            if ep.fault:
                fault_log.append("preview " + fault_line(ep.seed, ep.length, ep.fault))
            else:
                preview_returns.append(ep.ret)
            bar.advance(task)
        if not preview_returns:
            raise MotorlabError(f"all {preview} preview episodes ended on a numerical fault "
                                f"(first: {fault_log[0]}); check the env and the policy's run.")
        preview_returns = np.array(preview_returns)
        threshold = float(np.percentile(preview_returns, percentile))
        task = bar.add_task(f"episodes with return >= {threshold:.2f}", total=episodes)
        seeds = [seed + preview + i for i in range(max_episodes)]
        tried = 0
        for ep in _episodes(seeds, workers, init_args):
            tried += 1
            if ep.fault:
                fault_log.append(fault_line(ep.seed, ep.length, ep.fault))
            elif ep.ret >= threshold:
                kept.append(ep)
                bar.advance(task)
                if len(kept) == episodes:
                    break
    if not kept:
        raise MotorlabError(f"no episode in {tried} reached the threshold {threshold:.3g}; "
                            "lower --percentile or train the policy longer.")
    run = prepare_run_dir(out, "collect")
    acts = np.concatenate([e.activations for e in kept])
    meta = {"source_run": str(run_dir.resolve()), "env_id": cfg.id, "percentile": percentile, "preview": preview,
            "deterministic": deterministic, "seed": seed, "episodes_requested": episodes, "episodes_tried": tried}
    atomic_write_npz(run / ACTIVATIONS, activations=acts,
              episode=np.concatenate([np.full(e.length, i) for i, e in enumerate(kept)]),
              returns=np.array([e.ret for e in kept]), seeds=np.array([e.seed for e in kept]),
              solved=np.array([e.solved for e in kept]), threshold=np.array(threshold),
              preview_returns=preview_returns, metadata=np.array(json.dumps(meta)))
    write_config(run, {"run_dir": str(run_dir), "episodes": episodes, "percentile": percentile, "preview": preview,
                       "seed": seed, "deterministic": deterministic})
    summary = {"env_id": cfg.id, "samples": int(len(acts)), "n_muscles": int(acts.shape[1]),
               "episodes_kept": len(kept), "episodes_requested": episodes, "episodes_tried": tried,
               "threshold": threshold, "preview_return_mean": float(preview_returns.mean()),
               "kept_return_mean": float(np.mean([e.ret for e in kept])),
               "kept_success_rate": float(np.mean([e.solved for e in kept])), "numerical_faults": len(fault_log)}
    write_faults_log(run, fault_log)
    write_summary(run, summary)
    summary["run_dir"] = str(run)
    return summary
