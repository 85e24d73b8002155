"""`motorlab dynamics collect`: transitions (state, action, next state, reward, done).

Two collectors, one result format (transitions.py):
- Reacher with random actions runs in batches (`reacher_sim.rollout_reacher`): by default
  the arm's closed-form equations of motion in NumPy over all episodes at once (`closed-form`,
  tens of times Gymnasium's Python stepping), or MuJoCo's own step in C on every core
  (`mujoco`). Their transitions are the ones Gymnasium's env gives for the same initial state
  and actions: `mujoco` joint entries bit for bit, `closed-form` to MuJoCo's solver tolerance
  (tests/dynamics/test_collection.py).
- Any other env or policy (a trained run folder) steps Gymnasium envs in a process
  pool, one episode per seed, so the result does not depend on the number of workers.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from rich.progress import Progress

from motorlab import processes
from motorlab.dynamics.layouts import env_layout
from motorlab.dynamics.reacher_sim import arm_models, closed_form_arm, rollout_reacher, sample_initial_states
from motorlab.dynamics.state import StateLayout
from motorlab.dynamics.transitions import Transitions
from motorlab.envs import EnvConfig, describe_env, env_record, facts, is_bare, make_env, option_name
from motorlab.envs.spaces import encode_space, flat_space, require_actions
from motorlab.errors import MotorlabError
from motorlab.faults import fault_line, fault_of
from motorlab.policies import load_policy_files, load_run_policy

CHUNK = 4000  # episodes per batched rollout: bounds memory, paces the progress bar
SIMULATORS = ("auto", "closed-form", "mujoco", "gymnasium")


def _is_reacher(env: gym.Env) -> bool:
    """Reacher-v4/v5 (the catalogue's closed_form "reacher") whose model is its XML's layout: what
    `rollout_reacher` reproduces exactly."""
    spec = env.spec.id if env.spec else ""
    if not (facts(spec).closed_form == "reacher" and env.observation_space.shape[0] in (10, 11)):
        return False
    try:
        arm_models(env)
    except MotorlabError:
        return False
    return True


def episode_arrays(obs, actions, rewards, terminated, truncated, layout: StateLayout, episode_ids):
    """Transitions from per-episode observation sequences (T+1 rows each)."""
    states = [layout.state(o[:-1]) for o in obs]
    return dict(
        states=np.concatenate(states), next_states=np.concatenate([layout.state(o[1:]) for o in obs]),
        goals=np.concatenate([layout.goal(o[:-1]) for o in obs]), actions=np.concatenate(actions),
        rewards=np.concatenate(rewards), terminated=np.concatenate(terminated),
        dones=np.concatenate([te | tr for te, tr in zip(terminated, truncated)]),
        episode=np.concatenate([np.full(len(s), i) for s, i in zip(states, episode_ids)]),
    )


def random_actions(rng: np.random.Generator, low: np.ndarray, high: np.ndarray, episodes: int, steps: int,
                   beta: float) -> np.ndarray:
    """(episodes, steps, A) random actions within [low, high]. beta 0: independent uniform draws; beta > 0:
    each action dimension is Gaussian noise whose power falls as 1/f^beta along time (1 pink, 2 red:
    slow, sweeping commands that carry a body across its workspace, where white noise jitters in place),
    mapped through the normal CDF, so each action is spread over its bounds near uniformly (a Gaussian copula; a
    short red sequence leans to its ends)."""
    if beta == 0:
        return rng.uniform(low, high, size=(episodes, steps, len(low)))
    import colorednoise
    from scipy.special import ndtr

    z = colorednoise.powerlaw_psd_gaussian(beta, (episodes, len(low), steps), random_state=rng)
    z /= z.std(axis=-1, keepdims=True).clip(min=1e-12)  # unit variance per sequence: a uniform spread in bounds
    return low + (high - low) * ndtr(z).transpose(0, 2, 1)


def _collect_reacher(env, episodes: int, seed: int, layout: StateLayout, workers: int, simulator: str,
                     bar, task, noise_beta: float = 0.0) -> dict:
    rng = np.random.default_rng(seed)
    steps = env.spec.max_episode_steps or 50
    low, high = env.action_space.low, env.action_space.high
    obs_dim = env.observation_space.shape[0]
    state_dim, goal_dim = layout.state(np.zeros(obs_dim)).shape[0], layout.goal(np.zeros(obs_dim)).shape[0]
    # equal-length episodes: whole-array state extraction, written chunk by chunk into arrays
    # sized for every episode (no per-episode Python, no concatenation of the parts)
    rows = episodes * steps
    out = dict(states=np.empty((rows, state_dim)), next_states=np.empty((rows, state_dim)),
               goals=np.empty((rows, goal_dim)), actions=np.empty((rows, len(low))), rewards=np.empty(rows),
               terminated=np.zeros(rows, dtype=bool), dones=np.zeros(rows, dtype=bool),
               episode=np.empty(rows, dtype=np.int64))
    filled, faults = 0, []
    for start in range(0, episodes, CHUNK):
        n = min(CHUNK, episodes - start)
        qpos, qvel = sample_initial_states(env, n, rng)
        actions = random_actions(rng, low, high, n, steps, noise_beta)
        obs, rewards = rollout_reacher(env, qpos, qvel, actions, threads=workers, simulator=simulator)
        bad = ~(np.isfinite(obs).all(axis=(1, 2)) & np.isfinite(rewards).all(axis=1))
        faults += [f"seed={seed} episode={start + i}: non-finite observation or reward" for i in np.flatnonzero(bad)]
        if bad.any():
            obs, rewards, actions = obs[~bad], rewards[~bad], actions[~bad]
        ids = np.arange(start, start + n)[~bad]
        block = slice(filled, filled + len(ids) * steps)
        out["states"][block] = layout.state(obs[:, :-1]).reshape(-1, state_dim)
        out["next_states"][block] = layout.state(obs[:, 1:]).reshape(-1, state_dim)
        out["goals"][block] = layout.goal(obs[:, :-1]).reshape(len(ids) * steps, goal_dim)  # goal_dim may be 0
        out["actions"][block] = actions.reshape(-1, len(low))
        out["rewards"][block] = rewards.reshape(-1)
        out["episode"][block] = np.repeat(ids, steps)
        out["dones"][block.start + steps - 1:block.stop:steps] = True  # Reacher never terminates; the time
        filled = block.stop                                             # limit truncates each last step
        bar.advance(task, n)
    return {k: v[:filled] for k, v in out.items()}, faults


# ---- the Gymnasium pool: any env, random actions or a trained policy --------------

_worker: dict[str, Any] = {}


def _init_worker(env_cfg: dict, policy_dir: str | None, noise_beta: float = 0.0, parent: int | None = None) -> None:
    if parent is not None:  # a pool process: stopped by the parent's terminate(), or its death, not by Ctrl-C
        processes.serve_parent(parent)
    torch.set_num_threads(1)
    _worker["env"] = make_env(EnvConfig.model_validate(env_cfg))
    _worker["policy"] = load_policy_files(Path(policy_dir)) if policy_dir else None
    _worker["noise_beta"] = noise_beta


def _run_episode(seed: int) -> tuple:
    env, policy = _worker["env"], _worker["policy"]
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    if policy is not None:
        policy.reset(1)
    low, high = env.action_space.low, env.action_space.high
    observations, actions, rewards, terminated, truncated = [obs], [], [], [], []
    fault, done = None, False
    # random actions come a block at a time (the episode's time limit, at most 1,000 steps): colored
    # noise is drawn along a whole sequence
    block = min(env.spec.max_episode_steps or 1000, 1000) if env.spec is not None else 1000
    planned: list[np.ndarray] = []
    while not done:
        if policy is None:
            if not planned:
                planned = list(random_actions(rng, low, high, 1, block, _worker.get("noise_beta", 0.0))[0])
            action = planned.pop(0)
        else:
            action = np.asarray(policy.act(obs[None])[0])
        obs, reward, term, trunc, info = env.step(action)
        fault = fault_of(info)
        if fault:  # the episode ends here, and _collect_pool leaves it out whole (whole_episodes)
            break
        done = term or trunc
        observations.append(obs)
        actions.append(action)
        rewards.append(reward)
        terminated.append(term)
        truncated.append(trunc)
    return (np.array(observations, dtype=np.float64), np.array(actions, dtype=np.float64).reshape(-1, *low.shape),
            np.array(rewards, dtype=np.float64), np.array(terminated, dtype=bool), np.array(truncated, dtype=bool),
            fault)


def _collect_pool(env_cfg: EnvConfig, policy_dir: str | None, episodes: int, seed: int, layout: StateLayout,
                  workers: int, bar, task, noise_beta: float = 0.0) -> dict:
    seeds = [seed + i for i in range(episodes)]
    init_args = (env_cfg.model_dump(), policy_dir, noise_beta)
    results = []
    if workers <= 1:
        _init_worker(*init_args)
        episode_iter = map(_run_episode, seeds)
    else:  # spawn: a fresh interpreter per worker is safe with torch and MuJoCo state
        pool = mp.get_context("spawn").Pool(workers, initializer=_init_worker, initargs=(*init_args, os.getpid()))
        episode_iter = pool.imap(_run_episode, seeds, chunksize=max(1, min(64, episodes // (4 * workers))))
    try:
        for r in episode_iter:
            results.append(r)
            bar.advance(task)
    finally:
        if workers > 1:
            pool.terminate()
    faults = [fault_line(s, len(r[1]) + 1, r[-1]) for s, r in zip(seeds, results) if r[-1]]
    kept = whole_episodes([r[-1] for r in results])
    if not kept:  # nothing to stack: collect_transitions' check of an empty collection says so
        return {"states": np.empty((0, layout.size))}, faults
    arrays = episode_arrays(*zip(*(results[i][:-1] for i in kept)), layout=layout, episode_ids=kept)
    return arrays, faults


def whole_episodes(faults: list[str | None]) -> list[int]:
    """The episodes kept: those that ended on no numerical fault. A faulted episode is left out whole, not
    cut at its fault: MuJoCo warns of a diverging state only once a value passes 1e10, so the steps
    before its warning were already leaving the physics. A generated arm's pink-noise episodes ran up
    to 1e7 rad/s first; kept, their few rows set the model's normalizers (a state change's std of 2e5)
    and every plan on that model went NaN (benchmarks/mbrl_bodies.py, headline body 100)."""
    return [i for i, fault in enumerate(faults) if not fault]


def require_continuous(env: gym.Env, env_id: str, user: str, random: bool = False) -> None:
    """Refuse, in one line, an env whose actions a forward model cannot take: not a Box (a discrete
    choice), or, for uniformly random actions (`random`), a Box without finite bounds to draw them in.

    Raises:
        MotorlabError: naming the env, its action space and what fits it.
    """
    require_actions(env.action_space, user, env_id=env_id,
                    instead=f"learn it model-free instead, e.g. `motorlab train {env_id} --algo ppo`")
    space = env.action_space
    if random and not (np.isfinite(space.low).all() and np.isfinite(space.high).all()):
        raise MotorlabError(f"{user} draws random actions within the action bounds, and {env_id}'s are unbounded "
                            f"({space}); give your env finite action bounds (its action_space's low "
                            "and high) or collect with --policy RUN_DIR.")


def collect_transitions(env: str | EnvConfig, episodes: int, policy: str = "random", workers: int | None = None,
                        seed: int = 0, state: str = "auto", simulator: str = "auto",
                        progress: bool = True, before_work: Callable[[], None] | None = None,
                        noise_beta: float = 0.0) -> Transitions:
    """Transitions of `episodes` episodes of an env.

    Args:
        env: a Gymnasium (or MyoSuite) env id, or an EnvConfig: the env with motorlab's wrappers
            (delay, noise, history, reward shaping, synergy actions, ...), whose observations, actions
            and rewards are what the transitions record.
        episodes: number of episodes, each to its end (termination or time limit).
        policy: "random" (random actions, colored by `noise_beta`) or a run folder from `motorlab train`.
        workers: processes or threads (default: all cores).
        state: state layout, "auto" (the env's catalogue entry: reacher for Reacher ids, else the observation),
            "reacher", "observation".
        simulator: "auto" (for the bare Reacher with random actions the arm's closed form where it
            reproduces the model, else MuJoCo rollouts; Gymnasium for anything else, an env with
            wrappers or arguments included), "closed-form", "mujoco" or "gymnasium".
        progress: show a progress bar.
        before_work: called once the inputs are checked, before the first episode (`dynamics
            collect` refuses a finished run's --out there: a mistake in the input is named first,
            and a refusal costs no episodes).
        noise_beta: the random policy's color (`random_actions`): 0 white (independent uniform
            draws), 1 pink, 2 red.

    Raises:
        MotorlabError: bad counts, unknown env or layout, a policy folder that does not fit the env,
            closed-form or mujoco asked for an env with wrappers or arguments.
    """
    if episodes <= 0:
        raise MotorlabError(f"--episodes must be positive, got {episodes}.")
    if workers is not None and workers <= 0:
        raise MotorlabError(f"--workers must be positive, got {workers}.")
    if not (np.isfinite(noise_beta) and noise_beta >= 0):
        raise MotorlabError(f"--noise-beta must be a number >= 0 (0 white, 1 pink, 2 red), got {noise_beta}.")
    if noise_beta and policy != "random":
        raise MotorlabError("--noise-beta colors random actions; a --policy run folder chooses its own: drop one.")
    if simulator not in SIMULATORS:
        raise MotorlabError(f"--simulator {simulator!r}: choose {', '.join(SIMULATORS[:-1])} or {SIMULATORS[-1]}.")
    env_cfg = env if isinstance(env, EnvConfig) else EnvConfig(id=env)
    env_id = env_cfg.id
    bare = is_bare(env_cfg)
    if simulator in ("closed-form", "mujoco") and not bare:
        given = ", ".join(option_name(k) for k in env_record(env_cfg) if k != "id")
        raise MotorlabError(f"--simulator {simulator} steps the bare Reacher arm and cannot apply {given} "
                            f"({describe_env(env_cfg)}); use --simulator gymnasium (auto picks it).")
    env = make_env(env_cfg)  # reward shaping (--reward) too: the rewards recorded are the ones a learned head fits
    try:  # the env closed whatever ends the collection: a refused input, a fault, the end
        # before any work: one line for an env a forward model cannot act on
        require_continuous(env, env_id, "dynamics collect", random=policy == "random")
        layout = env_layout(env, env_id, state)
        policy_dir = None
        if policy != "random":
            policy_dir = str(Path(policy).resolve())
            if not Path(policy).exists():
                raise MotorlabError(f"--policy {policy!r} is neither 'random' nor a run folder from `motorlab train`.")
            expected = getattr(getattr(load_run_policy(Path(policy)), "policy", None), "observation_space", None)
            if expected is not None:  # a policy trained on a Dict observation acts on its flat vector here
                expected = flat_space(expected)
            if expected is not None and expected.shape != env.observation_space.shape:
                raise MotorlabError(f"the policy in {policy} expects observations of shape {expected.shape}, "
                                    f"{env_id} gives {env.observation_space.shape}; pick the env it was trained on.")
        fast = _is_reacher(env) and policy_dir is None and bare
        if simulator in ("closed-form", "mujoco") and not fast:
            raise MotorlabError(f"--simulator {simulator} covers Reacher with random actions only; "
                                "use auto or gymnasium.")
        fast = fast and simulator != "gymnasium"
        used = "gymnasium"
        if fast:
            closed = closed_form_arm(env) is not None
            if simulator == "closed-form" and not closed:
                raise MotorlabError("this Reacher arm's dynamics are not the closed form's (it did not reproduce "
                                    "MuJoCo's accelerations); use --simulator mujoco.")
            used = "closed-form" if closed and simulator != "mujoco" else "mujoco"
        if before_work is not None:
            before_work()
        workers = workers or os.cpu_count() or 1
        start = time.perf_counter()
        with Progress(disable=not progress, transient=False) as bar:
            task = bar.add_task(f"{env_id} episodes", total=episodes)
            if fast:
                arrays, faults = _collect_reacher(env, episodes, seed, layout, workers, used, bar, task,
                                                  noise_beta)
            else:
                arrays, faults = _collect_pool(env_cfg, policy_dir, episodes, seed, layout, workers, bar, task,
                                               noise_beta)
        if len(arrays["states"]) == 0:
            raise MotorlabError(f"every episode of {env_id} ended on a numerical fault (first: {faults[0]}); "
                                "nothing to collect. A diverging simulation: a smaller timestep, more joint damping "
                                "or armature, or the RK4 integrator in the model's XML makes it stable.")
        seconds = time.perf_counter() - start
        meta = {"env_id": env_id, "env": env_record(env_cfg), "state_layout": layout.name,
                "state_labels": list(layout.labels), "goal_labels": list(layout.goal_labels),
                "obs_dim": int(env.observation_space.shape[0]),
                "obs_layout": layout.keys_json(), "action_space": encode_space(env.action_space),
                "action_low": env.action_space.low.tolist(), "action_high": env.action_space.high.tolist(),
                "policy": policy_dir or "random", "seed": seed, "episodes": episodes,
                "simulator": used, "workers": workers, "seconds": seconds,
                "numerical_faults": len(faults), "fault_log": faults}
        return Transitions(**arrays, meta=meta).check()
    finally:
        env.close()
