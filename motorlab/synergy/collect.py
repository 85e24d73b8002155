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
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import Progress

from motorlab.envs import EnvConfig, make_env, max_return
from motorlab.errors import MotorlabError
from motorlab.evaluation import EpisodeSuccess, success_mode, trained_env_settings
from motorlab.faults import fault_line, fault_of
from motorlab.policies import load_policy_files
from motorlab.runs import atomic_write_npz, require_run_dir

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
    import torch  # heavy: the worker processes load it, not every command that reads these settings

    torch.set_num_threads(1)
    cfg = EnvConfig.model_validate(env_cfg)
    _worker["env"] = make_env(cfg, shaped=False)
    policy = load_policy_files(Path(run_dir))
    if hasattr(policy, "deterministic"):
        policy.deterministic = deterministic
    _worker["policy"] = policy

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


@dataclass
class Collection:
    """The kept episodes of a collection and how they were chosen."""

    env_id: str
    source_run: Path
    kept: list[Episode]
    preview_returns: np.ndarray
    threshold: float
    tried: int
    fault_log: list[str]  # faulted episodes neither set the threshold nor are kept: their activations diverged

    def activations(self) -> np.ndarray:
        """Every kept step's muscle activations, (samples, n_muscles)."""
        return np.concatenate([e.activations for e in self.kept])


def collect(run_dir: Path, episodes: int, percentile: float = 80.0, preview: int = 50, seed: int = 0,
            deterministic: bool = False, workers: int | None = None, max_episodes: int | None = None,
            progress: bool = True) -> Collection:
    """Muscle activations of `episodes` episodes at or above the preview's percentile.

    Args:
        run_dir: a finished training run (its policy and env are used).
        episodes: episodes to keep (N).
        percentile: P; the threshold is the P-th percentile of the preview returns.
        preview: episodes run first to set the threshold (M).
        deterministic: act with the policy's mean action instead of sampling.
        workers: processes (default: all cores).
        max_episodes: give up after this many episodes past the preview (default 20 N).

    Raises:
        MotorlabError: an env without muscles, or no episode reaching the threshold.
    """
    run_dir = require_run_dir(Path(run_dir))
    cfg = EnvConfig.model_validate(trained_env_settings(run_dir))
    probe = make_env(cfg)
    muscle_activations(probe)  # fail early for an env without muscles
    probe.close()
    workers = workers or os.cpu_count() or 1
    max_episodes = max_episodes or 20 * episodes
    init_args = (str(run_dir), cfg.model_dump(), deterministic)

    kept: list[Episode] = []
    fault_log: list[str] = []
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
    return Collection(cfg.id, run_dir, kept, np.array(preview_returns), threshold, tried, fault_log)


def save_activations(path: Path, c: Collection, meta: dict[str, Any]) -> None:
    """activations.npz: `activations` (S, n_muscles), `episode` (S,) index into the kept episodes,
    `returns` (N,), `seeds` (N,), `solved` (N,), `threshold`, `preview_returns` (M,) and
    `metadata` (JSON string). Plain arrays: loading it needs no pickle."""
    atomic_write_npz(path, activations=c.activations(),
                     episode=np.concatenate([np.full(e.length, i) for i, e in enumerate(c.kept)]),
                     returns=np.array([e.ret for e in c.kept]), seeds=np.array([e.seed for e in c.kept]),
                     solved=np.array([e.solved for e in c.kept]), threshold=np.array(c.threshold),
                     preview_returns=c.preview_returns, metadata=np.array(json.dumps(meta)))


def load_activations(path: Path) -> tuple[np.ndarray, dict]:
    """Activations (n_samples, n_muscles) and metadata from activations.npz (no pickle).

    Raises:
        MotorlabError: missing, not an npz, no `activations` array, wrong shape, NaN/Inf.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "activations.npz"
    if not path.is_file():
        raise MotorlabError(f"{path} does not exist; write it with `motorlab synergies collect RUN_DIR`.")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):  # a plain .npy array
            raise MotorlabError(f"{path} is a single array, not an .npz archive; write it with "
                                "`motorlab synergies collect` (activations.npz).")
        with loaded as data:
            if "activations" not in data.files:
                raise MotorlabError(f"{path} has no 'activations' array; it holds {', '.join(data.files) or 'nothing'}.")
            acts = np.asarray(data["activations"], dtype=np.float64)
            meta = json.loads(str(data["metadata"])) if "metadata" in data.files else {}
    except MotorlabError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as e:
        raise MotorlabError(f"{path} is not a readable .npz file ({e}); collect it again.") from None
    if acts.ndim != 2 or acts.shape[0] < 2 or acts.shape[1] < 1:
        raise MotorlabError(f"{path}: activations must be (samples, muscles) with at least 2 samples; got {acts.shape}.")
    if not np.all(np.isfinite(acts)):
        raise MotorlabError(f"{path}: activations contain NaN or Inf; collect them again.")
    return acts, meta
