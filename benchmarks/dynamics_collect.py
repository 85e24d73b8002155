"""Transition collection on Reacher-v5: motorlab's MuJoCo rollouts vs the reference Gymnasium pool.

Reference (the notebook approach): a multiprocessing pool with one worker per core, each
stepping Gymnasium's Reacher-v5 with random actions and extracting the 8-number state
(joint cos/sin, joint velocities, fingertip x-y = fingertip-target vector + target).
motorlab: `collect_transitions` with its default simulator for Reacher, the arm's closed-form
dynamics integrated in NumPy over all episodes at once (`closed-form`), and with MuJoCo's own
step through `mujoco.rollout` on all cores (`--simulator mujoco`). All collect the same
number of episodes; the rate counts transitions per second of wall time, start to arrays.

Identity: episodes rolled out by each motorlab simulator are replayed in Gymnasium's env from
the same initial state under the same actions. `mujoco`: joint entries bit for bit, the
fingertip and rewards to rounding (1e-12). `closed-form`: every entry to rounding (1e-12)
against MuJoCo with its constraint solver run to convergence (tolerance 0), and to that
solver's tolerance against the env's defaults (it stops at 1e-8 on the scaled cost while the
elbow presses on its limit; the difference is printed). A sample of the collected rows is
replayed from their first state, recovered from cos/sin.

Usage:  .venv/bin/python benchmarks/dynamics_collect.py [--episodes 20000] [--workers N]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import platform
import time

import gymnasium as gym
import numpy as np
from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

from motorlab.dynamics.collection import collect_transitions

TARGET_RATIO = 5.0
TARGET_RATE = 200_000
ISSUE_REFERENCE_RATE = 41_000  # the reference's rate on the machine the targets were set on (issue 4)


def _reference_episodes(args: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """One worker's share: `count` random-action episodes from seed `first`."""
    first, count = args
    env = gym.make("Reacher-v5")
    states, actions, next_states, rewards = [], [], [], []
    for k in range(count):
        obs, _ = env.reset(seed=first + k)
        env.action_space.seed(first + k)
        done = False
        while not done:
            a = env.action_space.sample()
            nxt, r, terminated, truncated, _ = env.step(a)
            for o, out in ((obs, states), (nxt, next_states)):
                out.append(np.r_[o[0:4], o[6:8], o[8:10] + o[4:6]])
            actions.append(a)
            rewards.append(r)
            obs, done = nxt, terminated or truncated
    return np.array(states), np.array(actions), np.array(next_states), np.array(rewards)


def reference_collect(episodes: int, workers: int) -> tuple[float, int]:
    start = time.perf_counter()
    share = -(-episodes // workers)
    jobs = [(i * share, min(share, episodes - i * share)) for i in range(workers) if i * share < episodes]
    with mp.get_context("fork").Pool(workers) as pool:
        parts = pool.map(_reference_episodes, jobs)
    n = sum(len(p[0]) for p in parts)
    return time.perf_counter() - start, n


def _exact_start_diffs(env, qpos, qvel, actions, obs, rewards) -> dict[str, float]:
    """Largest differences between a motorlab rollout and Gymnasium's env stepped from the same states."""
    joint = tip = reward = 0.0
    for e in range(len(qpos)):
        env.unwrapped.set_state(qpos[e], qvel[e])
        for t in range(actions.shape[1]):
            o, rew, *_ = env.step(actions[e, t])
            joint = max(joint, float(np.abs(obs[e, t + 1, :8] - o[:8]).max()))
            tip = max(tip, float(np.abs(obs[e, t + 1, 8:] - o[8:]).max()))
            reward = max(reward, abs(float(rewards[e, t] - rew)))
    return {"joint": joint, "tip_m": tip, "reward": reward}


def replay_check(data, episodes: int = 50, seed: int = 1) -> dict[str, float]:
    """Each simulator vs Gymnasium's env from the same initial states under the same actions, and a
    sample of the collected rows replayed in Gymnasium from their first state (qpos from cos/sin)."""
    from motorlab.dynamics.reacher_sim import rollout_reacher, sample_initial_states

    env = gym.make("Reacher-v5")
    env.reset(seed=0)
    rng = np.random.default_rng(seed)
    qpos, qvel = sample_initial_states(env, episodes, rng)
    actions = rng.uniform(-1, 1, size=(episodes, 50, 2))
    rolled = {name: rollout_reacher(env, qpos, qvel, actions, simulator=name) for name in ("mujoco", "closed-form")}
    out: dict[str, float] = {"replayed_episodes": episodes}
    for name, (obs, rewards) in rolled.items():
        for key, value in _exact_start_diffs(env, qpos, qvel, actions, obs, rewards).items():
            out[f"{name.replace('-', '_')}_max_{key}_diff"] = value
    env.unwrapped.model.opt.tolerance = 0.0  # MuJoCo's constraint solver to convergence
    for key, value in _exact_start_diffs(env, qpos, qvel, actions, *rolled["closed-form"]).items():
        out[f"closed_form_vs_converged_mujoco_max_{key}_diff"] = value
    joint = tip = reward = 0.0
    for e in np.linspace(0, data.episode.max(), episodes).astype(int):
        rows = np.flatnonzero(data.episode == e)
        s0 = data.states[rows[0]]
        env.unwrapped.set_state(np.r_[np.arctan2(s0[2:4], s0[0:2]), data.goals[rows[0]]], np.r_[s0[4:6], 0.0, 0.0])
        for r in rows:
            o, rew, *_ = env.step(data.actions[r])
            joint = max(joint, float(np.abs(data.next_states[r][:6] - np.r_[o[0:4], o[6:8]]).max()))
            tip = max(tip, float(np.abs(data.next_states[r][6:] - (o[8:10] + o[4:6])).max()))
            reward = max(reward, abs(float(data.rewards[r] - rew)))
    out.update({"collected_vs_converged_mujoco_max_joint_diff": joint, "collected_vs_converged_mujoco_max_tip_diff_m": tip,
                "collected_vs_converged_mujoco_max_reward_diff": reward})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20000, help="episodes per side (50 transitions each)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes / threads per side")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved rounds of both sides; medians are reported")
    args = parser.parse_args()
    recorder = Recorder("dynamics_collect")  # the git state and load, read as the run starts

    # Interleaved rounds (reference, then motorlab): a drift in the machine's speed hits both
    # sides alike; medians over rounds, and the median of the per-round ratios.
    ref_rates, rates, mujoco_rates, data = [], [], [], None
    for _ in range(args.repeats):
        ref_seconds, ref_n = reference_collect(args.episodes, args.workers)
        ref_rates.append(ref_n / ref_seconds)
        data = collect_transitions("Reacher-v5", args.episodes, workers=args.workers, progress=False)
        rates.append(len(data) / data.meta["seconds"])
        rolled = collect_transitions("Reacher-v5", args.episodes, workers=args.workers, simulator="mujoco",
                                     progress=False)
        mujoco_rates.append(len(rolled) / rolled.meta["seconds"])
    rate, ref_rate = float(np.median(rates)), float(np.median(ref_rates))
    ratio = float(np.median(np.array(rates) / np.array(ref_rates)))
    check = replay_check(data)
    converged = [check[f"closed_form_vs_converged_mujoco_max_{k}_diff"] for k in ("joint", "tip_m", "reward")]
    defaults = [check[f"closed_form_max_{k}_diff"] for k in ("joint", "tip_m", "reward")]
    identical = (data.meta["simulator"] == "closed-form" and max(converged) < 1e-12 and max(defaults) < 1e-5
                 and check["mujoco_max_joint_diff"] == 0.0 and check["mujoco_max_tip_m_diff"] < 1e-12
                 and check["mujoco_max_reward_diff"] < 1e-12)
    recorder.record({
        "benchmark": "dynamics_collect", "env_id": "Reacher-v5", "episodes": args.episodes,
        "workers": args.workers, "cpus": os.cpu_count(), "machine": platform.processor() or platform.machine(),
        "motorlab_simulator": data.meta["simulator"],
        "motorlab_transitions_per_second": rate, "motorlab_rates": rates,
        "motorlab_mujoco_rollout_transitions_per_second": float(np.median(mujoco_rates)),
        "ratio_mujoco_rollout": float(np.median(np.array(mujoco_rates) / np.array(ref_rates))),
        "reference_transitions_per_second": ref_rate, "reference_rates": ref_rates,
        "ratio": ratio, "target_ratio": TARGET_RATIO, "target_rate": TARGET_RATE,
        # The issue's 200k/s is 5x the 41k/s its reference made on the machine it was measured on;
        # machines here differ in speed, so both verdicts are printed.
        "identical_transitions": identical,
        "meets_ratio_target": ratio >= TARGET_RATIO and identical,
        "meets_rate_target": rate >= TARGET_RATE,
        # how much slower this machine runs the reference than the issue's did: the rate
        # target scaled by it is the ratio target again
        "machine_slowdown_vs_issue": ISSUE_REFERENCE_RATE / ref_rate,
        **check,
    })


if __name__ == "__main__":
    main()
