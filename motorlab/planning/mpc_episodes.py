"""MPC episodes: an env controlled by CEM on a learned forward model; returns, distances, timing.

Episodes run in groups of `parallel` Gymnasium envs whose plans are made in one batched
planner call per control step (Brax-style batching: the model sees all envs' candidates at
once). `plan_ms_median` is the planning time per env per control step, i.e. a call's time
divided by the envs it planned for; `plan_call_ms_median` is the call's own latency.
With `parallel = 1` (the default) the two are the same.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from rich.progress import Progress

from motorlab.dynamics.layouts import env_layout
from motorlab.dynamics.model import ForwardModel, device_for, load_model
from motorlab.dynamics.planner_rewards import resolve_task
from motorlab.envs import EnvConfig, describe_env, env_record, make_env
from motorlab.envs.spaces import require_actions
from motorlab.errors import MotorlabError
from motorlab.faults import fault_line, fault_of
from motorlab.planning.mpc import FaultCounts, MPCPolicy, PlannerFaults, model_scorer
from motorlab.planning.planners import make_planner
from motorlab.report.video import filming, record_episode, write_mp4


def build_policy(env, env_id: str | EnvConfig, model: Path | ForwardModel, optimizer: str = "cem", seed: int = 0,
                 threads: int | None = 1, reward: str = "auto", termination: str = "auto", propagation: str = "mean",
                 particles: int | None = None, device: str = "cpu", termination_draws: int = 0,
                 termination_margin: float = 0.0, explore: float = 0.0, **settings) -> MPCPolicy:
    """An MPC policy for `env` on a forward model (or the model folder holding one), checked against the
    env and its layout. `env_id`: the env's id, or the EnvConfig it was made from (its --sar makes the
    planner's actions synergies). `reward` and `termination` say what it scores
    (motorlab.dynamics.planner_rewards.resolve_task); `settings` are the optimizer's (horizon, population,
    iterations, elites or temperature); `explore`: MPCPolicy's exploration noise."""
    cfg = env_config(env_id)
    env_id = cfg.id
    require_plannable(env, env_id)
    where = model if isinstance(model, ForwardModel) else Path(model)
    if not isinstance(model, ForwardModel):
        model = load_model(model, env_id=env_id)
    fitted = _fitted_env(model, cfg)
    try:
        layout = env_layout(env, env_id, model.meta.get("state_layout", "observation"))
    except MotorlabError:
        if fitted is None:
            raise
        raise MotorlabError(f"{where} was fit on {fitted}, not {describe_env(cfg)}: plan on the env it was fit on, "
                            "or refit it.") from None
    if model.state_size != layout.size or model.action_size != env.action_space.shape[0]:
        fix = f"plan on the env it was fit on ({fitted}) or refit it" if fitted else "refit the model"
        raise MotorlabError(f"{where} predicts {model.state_size} state entries from {model.action_size} "
                            f"actions; {describe_env(cfg)} has {layout.size} and {env.action_space.shape[0]}: {fix}.")
    if model.meta.get("obs_layout") != layout.keys_json():
        raise MotorlabError(f"{where} was fit on observations whose Dict keys lie at {_keys(model.meta.get('obs_layout'))}, "
                            f"{env_id}'s at {_keys(layout.keys_json())}; refit the model on {env_id}'s transitions.")
    task = resolve_task(env_id, layout.name, layout.size, model.action_size, len(layout.goal_labels), reward,
                        termination, frozenset(model.heads), achieved=layout.achieved, frames=layout.frames,
                        synergies=bool(cfg.sar))
    dev = device_for(device)
    if threads and dev.type == "cpu":
        torch.set_num_threads(threads)  # small batches: more threads cost more than they give
    model = model.to(dev)
    # the particles' own noise (probabilistic members), apart from the optimizer's samples
    faults = PlannerFaults()
    score = model_scorer(model, task, propagation=propagation, particles=particles,
                         generator=torch.Generator(dev).manual_seed(seed + 7919), faults=faults,
                         termination_draws=termination_draws, termination_margin=termination_margin)
    planner = make_planner(optimizer, score, env.action_space.low, env.action_space.high, seed=seed, device=dev,
                           faults=faults, **settings)
    policy = MPCPolicy(planner, layout, model, dev, explore=explore, seed=seed + 104729)
    policy.task = task
    return policy


def _fitted_env(model: ForwardModel, cfg: EnvConfig) -> str | None:
    """The env settings the model's transitions were collected under, in a few words, where the model
    records them (model.json's "env") and they differ from `cfg`'s; else None."""
    fitted = model.meta.get("env")
    if not isinstance(fitted, dict) or fitted == env_record(cfg):
        return None
    try:
        return describe_env(EnvConfig.model_validate(fitted))
    except (ValueError, MotorlabError):  # a damaged record: the sizes speak for themselves
        return None


def env_config(env: str | EnvConfig) -> EnvConfig:
    """An env id as the EnvConfig of the bare env; an EnvConfig as it is."""
    return env if isinstance(env, EnvConfig) else EnvConfig(id=env)


def require_plannable(env, env_id: str, user: str = "MPC") -> None:
    """Refuse, in one line, an env the planner cannot act on: actions that are not a Box, or a Box
    without finite bounds (the planner samples action sequences within them). `user`: who refuses."""
    require_actions(env.action_space, user, env_id=env_id,
                    instead=f"learn it model-free instead, e.g. `motorlab train {env_id} --algo ppo`")
    space = env.action_space
    if not (np.isfinite(space.low).all() and np.isfinite(space.high).all()):
        raise MotorlabError(f"{user} samples actions within the action bounds, and {env_id}'s are unbounded "
                            f"({space}); give your env finite action bounds (its action_space's low and high).")


def _keys(layout: list[dict] | None) -> str:
    """A recorded obs_layout in a few words: "achieved_goal 0:2, desired_goal 2:4, ..." or that there is none."""
    if not layout:
        return "(none: not a Dict observation)"
    return ", ".join(f"{k.get('key')} {k.get('start')}:{k.get('stop')}" for k in layout)


def _distance(layout, obs: np.ndarray) -> float:
    """Distance to the goal for layouts that know both ends (`StateLayout.reached`): the fingertip's to the
    target (reacher), the achieved_goal's to the desired_goal (a Dict observation with both); else NaN."""
    reached = layout.reached
    if reached is None or len(reached.columns) != len(layout.goal_labels):
        return float("nan")
    return float(np.linalg.norm(layout.state(obs)[list(reached.columns)] - layout.goal(obs)))


class EpisodePath(NamedTuple):
    """One episode as it happened: observations (T+1, obs), actions (T, A), rewards, terminated, truncated (T,)."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray


class MPCEpisodes(NamedTuple):
    returns: np.ndarray  # (episodes,)
    distances: np.ndarray  # (episodes, steps + 1), fingertip-to-target, padded with each episode's last
    call_ms: np.ndarray  # planning time of each call (all parallel envs at once)
    per_env_ms: np.ndarray  # the same per env
    fault_log: list[str]  # one line per episode ended by a numerical fault
    paths: list[EpisodePath] | None = None  # each episode's transitions, when recorded
    planner: FaultCounts = FaultCounts()  # the non-finite predictions and rewards the planner met
    first_planner_fault: str | None = None  # where the planner first met one: "seed=S step=T"
    faulted: tuple[int, ...] = ()  # the episodes (their index) that ended on a numerical fault


def planner_fault_line(counts: FaultCounts, reward: str, model: str, first: str | None = None) -> str:
    """One line for faults.log and the warning: what the planner met of non-finite numbers."""
    fallbacks = (f"; {counts.fallbacks} plan{'s' * (counts.fallbacks != 1)} had no usable candidate and fell back "
                 "to the previous plan (the middle of the action range at an episode's start)") if counts.fallbacks else ""
    where = f"; first at {first}" if first else ""
    return (f"planner: {counts.faulty_plans} of {counts.plans} plans met NaN/Inf numbers: {counts.rewards} "
            f"candidate{'s' * (counts.rewards != 1)} with a NaN/Inf reward (reward {reward}), {counts.states} with "
            f"NaN/Inf predicted states (model {model}), all rejected{fallbacks}{where}")


def run_episodes(env: str | EnvConfig, policy: MPCPolicy, episodes: int, seed: int, parallel: int,
                 progress: bool = True, seeds: list[int] | None = None, record: bool = False) -> MPCEpisodes:
    """Episodes of `policy` in `env` (an id, or an EnvConfig with its wrappers), `parallel` at a time:
    returns, per-step distances, planning times, and with `record` each episode's transitions.
    Episode i resets with `seeds[i]` (default seed + i)."""
    cfg = env_config(env)
    env_id = cfg.id
    seeds = list(seeds) if seeds is not None else [seed + i for i in range(episodes)]
    envs = [make_env(cfg, shaped=False) for _ in range(parallel)]
    returns, distances, call_ms, per_env_ms, fault_log, paths, faulted = [], [], [], [], [], [], []
    before, first_fault = policy.faults.counts(), None
    with Progress(disable=not progress) as bar:
        task = bar.add_task(f"MPC on {env_id}", total=episodes)
        for first in range(0, episodes, parallel):
            group = envs[:min(parallel, episodes - first)]
            obs = np.stack([e.reset(seed=seeds[first + i])[0] for i, e in enumerate(group)])
            first_obs = obs.copy()
            policy.reset(len(group))
            live = np.ones(len(group), dtype=bool)
            ret = np.zeros(len(group))
            dist = [[_distance(policy.layout, o)] for o in obs]
            steps: list[list[tuple]] = [[] for _ in group]  # (obs, action, reward, terminated, truncated)
            while live.any():
                start = time.perf_counter()
                actions = policy.act(obs)
                ms = (time.perf_counter() - start) * 1000
                call_ms.append(ms)
                per_env_ms.append(ms / len(group))
                if first_fault is None and policy.faults.counts().faulty_plans > before.faulty_plans:
                    live_seeds = ",".join(str(seeds[first + i]) for i in np.flatnonzero(live))
                    first_fault = f"step {len(dist[int(np.flatnonzero(live)[0])]) - 1} of seed={live_seeds}"
                for i in np.flatnonzero(live):
                    o, r, terminated, truncated, info = group[i].step(actions[i])
                    if record:
                        steps[i].append((o, np.array(actions[i]), r, terminated, truncated))
                    obs[i] = o
                    ret[i] += r
                    dist[i].append(_distance(policy.layout, o))
                    live[i] = not (terminated or truncated)
                    fault = fault_of(info)
                    if fault:
                        fault_log.append(fault_line(seeds[first + i], len(dist[i]) - 1, fault))
                        faulted.append(first + i)
            for i, rows in enumerate(steps if record else ()):
                o, a, r, te, tr = zip(*rows)
                paths.append(EpisodePath(np.array([first_obs[i], *o], dtype=np.float64), np.array(a, dtype=np.float64),
                                         np.array(r, dtype=np.float64), np.array(te, dtype=bool),
                                         np.array(tr, dtype=bool)))
            returns.extend(ret)
            distances.extend(dist)
            bar.advance(task, len(group))
    for e in envs:
        e.close()
    length = max(len(d) for d in distances)
    padded = np.array([d + [d[-1]] * (length - len(d)) for d in distances])
    planner = policy.faults.counts()
    planner = FaultCounts(*(getattr(planner, k) - getattr(before, k) for k in FaultCounts.__dataclass_fields__))
    return MPCEpisodes(np.array(returns), padded, np.array(call_ms), np.array(per_env_ms), fault_log,
                       paths if record else None, planner, first_fault, tuple(sorted(set(faulted))))


def record_video(env: str | EnvConfig, policy: MPCPolicy, path: Path, seed: int) -> Path:
    """One episode of `policy` in `env` (an id, or an EnvConfig) rendered to an MP4 at `path`."""
    with filming(make_env(env_config(env), shaped=False), 480, 480, None) as (env, cam, every, fps):
        frames, _ = record_episode(env, policy, cam, seed, every)
        write_mp4(path, frames, fps)
    return path
