"""`motorlab synergies collect`: the motor commands of a trained policy's good episodes, the
data a synergy fit (motorlab.synergies) starts from.

Preview episodes set a return threshold at the P-th percentile; then episodes are
run until N of them reach it, and one motor signal per step is kept, read after
each step from the unwrapped env (see `SIGNALS`): muscle activations (MuJoCo's
`data.act`), the actuator controls MuJoCo applied (`data.ctrl`, clamped to the
ctrlrange as the actuators get it), or the env's action. Episodes run in a process
pool, each from its own seed, so the result does not depend on the number of workers.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from rich.progress import Progress

from motorlab import processes
from motorlab.envs import EnvConfig, make_env, max_return
from motorlab.envs.catalog import facts
from motorlab.envs.spaces import require_actions
from motorlab.errors import MotorlabError
from motorlab.evaluation import EpisodeSuccess, success_mode, trained_env_settings
from motorlab.faults import fault_line, fault_of
from motorlab.policies import load_policy_files
from motorlab.runs import NpzUnreadable, atomic_write_npz, read_npz, require_run_dir

ACTIVATIONS = "activations.npz"

# What `collect --signal` records; "auto" is the first of act, ctrl, action the env has.
SIGNALS = ("auto", "act", "ctrl", "action")
SIGNAL_NAMES = {"act": "muscle activations", "ctrl": "actuator controls", "action": "actions"}


@dataclass
class Episode:
    seed: int
    ret: float
    length: int
    solved: bool
    activations: np.ndarray  # (length, n_signals): the recorded signal after each step
    fault: str | None = None  # the numerical fault that ended it; such episodes are never kept


def mujoco_of(env) -> tuple[Any, Any] | None:
    """(model, data) of a MuJoCo env (Gymnasium's `model`/`data`, MyoSuite's too), else None."""
    base = env.unwrapped
    model = getattr(base, "mj_model", None) or getattr(base, "model", None)
    data = getattr(base, "mj_data", None) or getattr(base, "data", None)
    if model is None or data is None or not hasattr(data, "ctrl") or not hasattr(model, "nu"):
        return None
    return model, data


def _env_name(env) -> str:
    return env.spec.id if env.spec else type(env.unwrapped).__name__


def muscle_activations(env) -> np.ndarray:
    """The current muscle activations of a MuJoCo env (data.act)."""
    found = mujoco_of(env)
    act = getattr(found[1], "act", None) if found else None
    if act is None or act.size == 0:
        raise MotorlabError(f"{_env_name(env)} has no muscle activations (MuJoCo data.act is empty); "
                            "record its actuator controls or actions instead: --signal ctrl or --signal action.")
    return np.array(act, dtype=np.float32)


def resolve_signal(env, signal: str = "auto") -> str:
    """The signal `collect` records on `env`: `signal` itself, checked, or for "auto" MuJoCo's
    data.act where the model has activation states (muscles), else data.ctrl where it has
    actuators, else the env's action.

    Raises:
        MotorlabError: an unknown signal, or one the env does not have.
    """
    if signal not in SIGNALS:
        raise MotorlabError(f"unknown --signal {signal!r}; choose one of {', '.join(SIGNALS)}.")
    found = mujoco_of(env)
    has_act = found is not None and found[0].na > 0
    has_ctrl = found is not None and found[0].nu > 0
    if signal == "auto":
        return "act" if has_act else "ctrl" if has_ctrl else "action"
    if signal == "act" and not has_act:
        muscle_activations(env)  # its message names the env and the other signals
    if signal == "ctrl" and not has_ctrl:
        raise MotorlabError(f"{_env_name(env)} has no MuJoCo actuators (data.ctrl); use --signal action.")
    if signal == "action" and not isinstance(env.action_space, gym.spaces.Box):
        raise MotorlabError(f"{_env_name(env)} has a {type(env.action_space).__name__} action space; "
                            "synergies need a Box of continuous actions.")
    return signal


def signal_bounds(env, signal: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-element (low, high) of a resolved signal: [0, 1] for muscles' act (an activation
    state of another kind: its actrange if limited, else unbounded), the actuator ctrlrange
    for ctrl (unbounded where not ctrllimited), the action space for action."""
    if signal == "action":
        space = env.action_space
        return space.low.astype(np.float64).ravel(), space.high.astype(np.float64).ravel()
    model, _ = mujoco_of(env)
    if signal == "ctrl":
        limited = model.actuator_ctrllimited.astype(bool)
        rng = model.actuator_ctrlrange
        return np.where(limited, rng[:, 0], -np.inf), np.where(limited, rng[:, 1], np.inf)
    import mujoco  # MuJoCo envs only reach here

    low, high = np.full(model.na, -np.inf), np.full(model.na, np.inf)
    for i in range(model.nu):
        first, count = model.actuator_actadr[i], model.actuator_actnum[i]
        if first < 0:
            continue  # a stateless actuator (motor, position servo)
        if model.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE:
            low[first:first + count], high[first:first + count] = 0.0, 1.0
        elif model.actuator_actlimited[i]:
            low[first:first + count], high[first:first + count] = model.actuator_actrange[i]
    return low, high


def signal_names(env, signal: str, size: int) -> list[str]:
    """A name for each element of a resolved signal, read from the MuJoCo model: the actuator whose
    activation state (act) or control (ctrl) it is (MyoSuite's muscle names, a user model's actuator
    names); an action element is its actuator's where the action is one command per actuator. An
    unnamed actuator is `actuator<i>`; an element with no actuator is `<signal><k>`."""
    found = mujoco_of(env)
    if found is None:
        return [f"{signal}{k}" for k in range(size)]
    model = found[0]

    def actuator(i: int) -> str:
        return model.actuator(i).name or f"actuator{i}"

    if signal == "act":
        names = [f"act{k}" for k in range(model.na)]
        for i in range(model.nu):
            first, count = int(model.actuator_actadr[i]), int(model.actuator_actnum[i])
            for j in range(count if first >= 0 else 0):
                names[first + j] = actuator(i) if count == 1 else f"{actuator(i)}[{j}]"
        return names[:size] + [f"act{k}" for k in range(len(names), size)]
    if signal == "ctrl" or size == model.nu:
        return [actuator(i) for i in range(min(size, model.nu))] + [f"{signal}{k}" for k in range(model.nu, size)]
    return [f"{signal}{k}" for k in range(size)]


def read_signal(env, signal: str, action: np.ndarray, bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The signal after a step: data.act, data.ctrl or `action`, as float32; ctrl and action
    clipped to their bounds, as MuJoCo's ctrlrange clamp and the action space bound them
    (what the actuators got, not what the policy asked for)."""
    if signal == "act":
        return muscle_activations(env)
    value = mujoco_of(env)[1].ctrl if signal == "ctrl" else np.asarray(action).ravel()
    return np.clip(value, *bounds).astype(np.float32)


# ---- one worker: its own env and policy, loaded once --------------------------------

_worker: dict[str, Any] = {}


def _init_worker(run_dir: str, env_cfg: dict, deterministic: bool, signal: str = "act", parent: int | None = None) -> None:
    import torch  # heavy: the worker processes load it, not every command that reads these settings

    if parent is not None:  # a pool worker: stopped by its parent, and with it (motorlab.processes)
        processes.serve_parent(parent)

    torch.set_num_threads(1)
    cfg = EnvConfig.model_validate(env_cfg)
    _worker["env"] = make_env(cfg, shaped=False)
    policy = load_policy_files(Path(run_dir))
    if hasattr(policy, "deterministic"):
        policy.deterministic = deterministic
    _worker["policy"] = policy
    _worker["signal"] = signal
    _worker["bounds"] = signal_bounds(_worker["env"], signal)

    _worker["target"] = max_return(cfg.id)
    _worker["success"] = success_mode(cfg)
    _worker["success_keys"] = facts(cfg.id).success_keys


def _run_episode(seed: int) -> Episode:
    import torch

    env, policy = _worker["env"], _worker["policy"]
    torch.manual_seed(seed)  # stochastic actions repeat for the same seed
    obs, _ = env.reset(seed=seed)
    policy.reset(1)
    outcome = EpisodeSuccess(1, _worker["target"], _worker["success"], keys=_worker["success_keys"])
    signal, bounds = _worker["signal"], _worker["bounds"]
    acts, ret, done = [], 0.0, False
    while not done:
        action = policy.act(obs[None])[0]
        obs, reward, terminated, truncated, info = env.step(action)
        acts.append(read_signal(env, signal, action, bounds))
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
    with mp.get_context("spawn").Pool(workers, initializer=_init_worker, initargs=(*init_args, os.getpid())) as pool:
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
    signal: str = "act"  # what `activations` holds: act, ctrl or action
    low: np.ndarray | None = None  # the signal's per-element bounds
    high: np.ndarray | None = None
    names: list[str] | None = None  # each element's name: its actuator's in the MuJoCo model (signal_names)

    def activations(self) -> np.ndarray:
        """Every kept step's signal (muscle activations, controls or actions), (samples, n_signals)."""
        return np.concatenate([e.activations for e in self.kept])


def collect(run_dir: Path, episodes: int, percentile: float = 80.0, preview: int = 50, seed: int = 0,
            deterministic: bool = False, workers: int | None = None, max_episodes: int | None = None,
            progress: bool = True, signal: str = "auto", before_work: Callable[[], None] | None = None) -> Collection:
    """A motor signal of `episodes` episodes at or above the preview's percentile.

    Args:
        run_dir: a finished training run (its policy and env are used).
        episodes: episodes to keep (N).
        percentile: P; the threshold is the P-th percentile of the preview returns.
        preview: episodes run first to set the threshold (M).
        deterministic: act with the policy's mean action instead of sampling.
        workers: processes (default: all cores).
        max_episodes: give up after this many episodes past the preview (default 20 N).
        signal: what to record (`SIGNALS`): act, ctrl, action, or auto (see `resolve_signal`).
        before_work: called once the run and its signal are checked, before the first episode
            (`synergies collect` refuses a finished --out there).

    Returns:
        The kept episodes, the resolved signal and its bounds.

    Raises:
        MotorlabError: a signal the env does not have, or no episode reaching the threshold.
    """
    run_dir = require_run_dir(Path(run_dir))
    cfg = EnvConfig.model_validate(trained_env_settings(run_dir))
    probe = make_env(cfg)
    try:
        # synergies are a continuous map onto the actions (a SAR replaces a Box of them): refused before any episode
        require_actions(probe.action_space, "synergies collect", env_id=cfg.id,
                        instead="there are no continuous commands to find synergies in; collect from a policy of "
                        "an env with Box actions")
        signal = resolve_signal(probe, signal)  # fail early for a signal the env does not have
        low, high = signal_bounds(probe, signal)
        names = signal_names(probe, signal, len(low))
    finally:
        probe.close()
    if before_work is not None:
        before_work()
    workers = workers or os.cpu_count() or 1
    max_episodes = max_episodes or 20 * episodes
    init_args = (str(run_dir), cfg.model_dump(), deterministic, signal)

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
    return Collection(cfg.id, run_dir, kept, np.array(preview_returns), threshold, tried, fault_log, signal, low, high,
                      names)


def save_activations(path: Path, c: Collection, meta: dict[str, Any]) -> None:
    """activations.npz: `activations` (S, n_signals), `episode` (S,) index into the kept episodes,
    `returns` (N,), `seeds` (N,), `solved` (N,), `threshold`, `preview_returns` (M,), `signal`
    (act, ctrl or action), `low` and `high` (n_signals,: its bounds, +-inf where unbounded), `names`
    (n_signals,: each element's actuator name, a unicode array) and `metadata` (JSON string, with
    `signal` too). Plain arrays: loading it needs no pickle."""
    n = c.kept[0].activations.shape[1]
    low = np.full(n, -np.inf) if c.low is None else c.low
    high = np.full(n, np.inf) if c.high is None else c.high
    names = c.names if c.names is not None and len(c.names) == n else [f"{c.signal}{k}" for k in range(n)]
    atomic_write_npz(path, activations=c.activations(), names=np.array(names, dtype=str),
                     episode=np.concatenate([np.full(e.length, i) for i, e in enumerate(c.kept)]),
                     returns=np.array([e.ret for e in c.kept]), seeds=np.array([e.seed for e in c.kept]),
                     solved=np.array([e.solved for e in c.kept]), threshold=np.array(c.threshold),
                     preview_returns=c.preview_returns, signal=np.array(c.signal),
                     low=np.asarray(low, dtype=np.float64), high=np.asarray(high, dtype=np.float64),
                     metadata=np.array(json.dumps({**meta, "signal": c.signal})))


def load_activations(path: Path) -> tuple[np.ndarray, dict]:
    """The recorded signal (n_samples, n_signals) and metadata from activations.npz (no pickle).

    The metadata always holds `signal` (files written before signals existed hold muscle
    activations: "act") and `low`/`high`, the signal's per-element bounds as float arrays
    ([0, 1] for those older files).

    Raises:
        MotorlabError: missing, not an npz, no `activations` array, wrong shape, NaN/Inf.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "activations.npz"
    if not path.is_file():
        raise MotorlabError(f"{path} does not exist; write it with `motorlab synergies collect RUN_DIR`.")
    try:
        data = read_npz(path)
    except NpzUnreadable as e:
        raise MotorlabError(f"{path} is not a readable .npz file ({e}); collect it again with "
                            "`motorlab synergies collect`.") from None
    if "activations" not in data:
        raise MotorlabError(f"{path} has no 'activations' array; it holds {', '.join(data) or 'nothing'}.")
    try:
        acts = np.asarray(data["activations"], dtype=np.float64)
        meta = json.loads(str(data["metadata"])) if "metadata" in data else {}
        bounds = {k: np.asarray(data[k], dtype=np.float64).ravel() for k in ("low", "high") if k in data}
    except (ValueError, TypeError) as e:  # strings where numbers belong, metadata that is not JSON
        raise MotorlabError(f"{path} is not an activations file written by `motorlab synergies collect` "
                            f"({str(e).splitlines()[0] if str(e) else type(e).__name__}); collect it again.") from None
    if not isinstance(meta, dict):
        raise MotorlabError(f"{path}: its metadata is not a JSON object; collect it again.")
    if "signal" in data:
        meta["signal"] = str(data["signal"])
    if acts.ndim != 2 or acts.shape[0] < 2 or acts.shape[1] < 1:
        raise MotorlabError(f"{path}: activations must be (samples, muscles) with at least 2 samples; got {acts.shape}.")
    if not np.all(np.isfinite(acts)):
        raise MotorlabError(f"{path}: activations contain NaN or Inf; collect them again.")
    meta.setdefault("signal", "act")  # written before signals existed: muscle activations
    n = acts.shape[1]
    default = (np.zeros(n), np.ones(n)) if meta["signal"] == "act" else (np.full(n, -np.inf), np.full(n, np.inf))
    for key, fallback in zip(("low", "high"), default, strict=True):
        value = bounds.get(key)
        meta[key] = value if value is not None and value.shape == (n,) else fallback
    meta["names"] = signal_labels(data, n, meta["signal"])
    episode = np.asarray(data["episode"]).ravel() if "episode" in data else None
    # each sample's episode (cross-validation holds out whole episodes); one episode where none is recorded
    meta["episode"] = episode.astype(np.int64) if episode is not None and episode.shape == (acts.shape[0],) \
        else np.zeros(acts.shape[0], dtype=np.int64)
    return acts, meta


def signal_labels(data: dict[str, Any], n: int, signal: str) -> list[str]:
    """The `names` array of an activations file as n distinct strings; generic ones (`act0`, ...) where
    it has none (files written before names were recorded) or they do not fit."""
    raw = data.get("names")
    names = [str(x) for x in np.asarray(raw).ravel()] if raw is not None else []
    if len(names) != n or len(set(names)) != n or any(not x for x in names):
        return [f"{signal}{k}" for k in range(n)]
    return names
