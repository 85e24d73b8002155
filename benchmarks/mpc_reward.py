"""Planning time per control step by what the planner scores with: a bundled reward, a user's reward, a learned head.

    .venv/bin/python benchmarks/mpc_reward.py [--episodes 60] [--steps 300] [--out PATH]

The issue's two targets, measured on Reacher-v5 with the "observation" state layout:
  - a user's torch reward (--reward MODULE:FUNCTION) plans as fast as the same reward bundled:
    median time per control step user / builtin <= 1.05;
  - a learned reward head (--reward learned, a model fit with --learn-reward) costs at most 1.5x the
    exact reward on a model of the same architecture otherwise: learned / builtin <= 1.5.

What runs
  Data: `--episodes` random Reacher-v5 episodes (50 steps each; 60 -> 3,000 transitions),
  motorlab.dynamics.collection.collect_transitions(state="observation", simulator="gymnasium"): the
  default closed-form Reacher collector fails on this layout (its goal has no entries and
  `reshape(-1, 0)` raises), so the episodes are stepped in Gymnasium's env.
  Models (motorlab.dynamics.train.fit_model, hidden (64, 64), `--epochs` epochs), in three groups, each
  fit twice, without heads and with heads=("reward",) (the same architecture but for the reward column):
    det1      1 deterministic member, mean propagation
    det5      5 deterministic members, mean propagation
    prob5_ts  5 probabilistic members, trajectory sampling (TS-inf, 5 particles: one per member)
  Rewards, per group: "builtin" (the bundled reacher_obs_v5, on the model without heads), "user" (the
  same arithmetic in benchmarks/user_reacher_reward.py, `--reward user_reacher_reward:reward` with
  benchmarks/ on sys.path, on the model without heads), "learned" (the reward head, on the model with
  it), and for information "builtin_on_head_model" (the bundled reward on the model with the head).
  Planner: motorlab.planning.mpc_episodes.build_policy(env, "Reacher-v5", model, "cem", seed, reward=...,
  propagation=..., horizon=15, population=100, iterations=5), one env, torch on 1 thread, CPU.

Measured
  The wall time of `policy.act(obs[None])` per control step (the plan only; the env step is not
  counted), `--steps` control steps per variant after 5 untimed warm-up steps, on the real env (an
  episode that ends is reset and the planner with it). The variants take turns in chunks of 25 steps
  so that other load on the machine falls on all of them alike. Reported: the median ms per step per
  variant, the ratios user / builtin and learned / builtin per group, the targets and whether each is
  met (per group and over all). Also: the median time of one reward call on a planner-sized batch
  (population x particles rows, horizon 15) for the bundled and the user's reward (their per-call
  overhead, free of the planner's noise), the mean env reward per step of each variant (a sanity
  check that every variant plans, not a comparison), and, by provenance.Recorder, the date, the
  command line, the git commit (and whether the tree was dirty), package versions, the CPU model, its
  cores and the load average at start and end.

Prints one JSON object; also writes it to benchmarks/results/mpc_reward.json (or --out), through a
temporary file renamed over it.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # benchmarks/user_reacher_reward.py, as a user's module on the path

from provenance import Recorder  # noqa: E402  (benchmarks/ is the script's folder)

from motorlab.dynamics.collection import collect_transitions  # noqa: E402
from motorlab.dynamics.train import fit_model  # noqa: E402
from motorlab.envs import EnvConfig, make_env  # noqa: E402
from motorlab.planning.mpc_episodes import build_policy  # noqa: E402

ENV_ID = "Reacher-v5"
USER_REWARD = "user_reacher_reward:reward"
TARGETS = {"user_over_builtin": 1.05, "learned_over_builtin": 1.5}
GROUPS = {  # name: (members, probabilistic, propagation)
    "det1": (1, False, "mean"),
    "det5": (5, False, "mean"),
    "prob5_ts": (5, True, "ts"),
}
VARIANTS = {  # name: (reward, the model with the reward head)
    "builtin": ("builtin", False),
    "user": (USER_REWARD, False),
    "learned": ("learned", True),
    "builtin_on_head_model": ("builtin", True),
}
PLANNER = {"horizon": 15, "population": 100, "iterations": 5}
CHUNK = 25
WARMUP = 5


def fit(data, members: int, probabilistic: bool, heads: tuple[str, ...], epochs: int, seed: int):
    model, metrics = fit_model(data, epochs=epochs, ensemble=members, probabilistic=probabilistic, heads=heads,
                               seed=seed, threads=1, progress=False)
    return model, {"valid_mse": metrics.get("valid_mse"), "epochs_run": metrics.get("epochs_run")}


def time_policies(policies: dict, steps: int, seed: int) -> tuple[dict[str, list[float]], dict[str, float]]:
    """ms per act() of each policy over `steps` control steps on its own env, the policies taking turns."""
    envs = {name: make_env(EnvConfig(id=ENV_ID), shaped=False) for name in policies}
    obs, episode = {}, {}
    for i, name in enumerate(policies):
        episode[name] = seed * 1000 + 100 * i
        obs[name] = envs[name].reset(seed=episode[name])[0]
        policies[name].reset(1)
    ms = {name: [] for name in policies}
    rewards = {name: [] for name in policies}

    def step(name: str, timed: bool) -> None:
        start = time.perf_counter()
        action = policies[name].act(obs[name][None])[0]
        elapsed = (time.perf_counter() - start) * 1000
        if timed:
            ms[name].append(elapsed)
        obs[name], r, terminated, truncated, _ = envs[name].step(action)
        rewards[name].append(float(r))
        if terminated or truncated:
            episode[name] += 1
            obs[name] = envs[name].reset(seed=episode[name])[0]
            policies[name].reset(1)

    for name in policies:
        for _ in range(WARMUP):
            step(name, False)
    while any(len(v) < steps for v in ms.values()):
        for name in policies:
            for _ in range(min(CHUNK, steps - len(ms[name]))):
                step(name, True)
    for env in envs.values():
        env.close()
    return ms, {name: float(np.mean(r)) for name, r in rewards.items()}


def reward_call_us(task_reward, rows: int, state_size: int, action_size: int, reps: int = 2000) -> float:
    """Median µs of one call of a task's reward on (rows, H, ...) tensors, as model_scorer calls it."""
    g = torch.Generator().manual_seed(0)
    h = PLANNER["horizon"]
    s, s2 = (torch.rand(rows, h, state_size, generator=g) for _ in range(2))
    a = torch.rand(rows, h, action_size, generator=g)
    goal = torch.zeros(rows, h, 0)
    times = []
    with torch.no_grad():
        for _ in range(reps):
            start = time.perf_counter()
            task_reward(s, a, s2, goal)
            times.append((time.perf_counter() - start) * 1e6)
    return statistics.median(times)


# ---------------------------------------------------------------------------------------- main

def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=60, help="random episodes to fit on (50 steps each)")
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--steps", type=int, default=300, help="timed control steps per variant")
    parser.add_argument("--groups", default=",".join(GROUPS), help="comma-separated subset of " + ", ".join(GROUPS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "mpc_reward.json")
    args = parser.parse_args()
    groups = [g.strip() for g in args.groups.split(",") if g.strip()]
    unknown = set(groups) - set(GROUPS)
    if unknown:
        parser.error(f"unknown groups {sorted(unknown)}; choose from {', '.join(GROUPS)}")

    # the git state and load now (what ran: the code the run's processes load as they start); --out's
    # folder and name, so a result written elsewhere is recorded the same way
    recorder = Recorder("mpc_reward", results=args.out.parent)
    started = time.perf_counter()
    torch.set_num_threads(1)
    data = collect_transitions(ENV_ID, args.episodes, seed=args.seed, state="observation", workers=1,
                               simulator="gymnasium", progress=False)  # see the docstring

    results, policies, fits, calls = {}, {}, {}, {}
    for group in groups:
        members, probabilistic, propagation = GROUPS[group]
        models = {}
        for with_head in (False, True):
            heads = ("reward",) if with_head else ()
            models[with_head], fits[f"{group}{'_reward_head' if with_head else ''}"] = fit(
                data, members, probabilistic, heads, args.epochs, args.seed)
        for variant, (reward, with_head) in VARIANTS.items():
            env = make_env(EnvConfig(id=ENV_ID), shaped=False)
            policies[(group, variant)] = build_policy(env, ENV_ID, models[with_head], "cem", args.seed, reward=reward,
                                                      propagation=propagation, **PLANNER)
            env.close()
        rows = PLANNER["population"] * (members if propagation == "ts" else 1)
        model = models[False]
        calls[group] = {v: round(reward_call_us(policies[(group, v)].task.reward, rows, model.state_size,
                                                model.action_size), 2) for v in ("builtin", "user")}

    ms, env_rewards = time_policies(policies, args.steps, args.seed)
    for group in groups:
        med = {v: statistics.median(ms[(group, v)]) for v in VARIANTS}
        ratios = {"user_over_builtin": med["user"] / med["builtin"],
                  "learned_over_builtin": med["learned"] / med["builtin"]}
        results[group] = {
            "members": GROUPS[group][0], "probabilistic": GROUPS[group][1], "propagation": GROUPS[group][2],
            "plan_ms_median": {v: round(m, 3) for v, m in med.items()},
            "plan_ms_p90": {v: round(float(np.percentile(ms[(group, v)], 90)), 3) for v in VARIANTS},
            "ratios": {k: round(v, 3) for k, v in ratios.items()},
            "meets": {k: ratios[k] <= TARGETS[k] for k in TARGETS},
            "reward_call_us_median": calls[group],
            "reward_call_user_over_builtin": round(calls[group]["user"] / calls[group]["builtin"], 3),
            "env_reward_per_step_mean": {v: round(env_rewards[(group, v)], 4) for v in VARIANTS},
        }

    recorder.record({
        "env_id": ENV_ID, "state_layout": "observation", "user_reward": USER_REWARD,
        "transitions": len(data), "fit": {"epochs": args.epochs, "hidden": [64, 64], "models": fits},
        "planner": {"optimizer": "cem", **PLANNER, "envs": 1, "device": "cpu"},
        "torch_threads": torch.get_num_threads(), "timed_steps_per_variant": args.steps, "chunk": CHUNK,
        "groups": results, "targets": TARGETS,
        "meets_targets": all(all(r["meets"].values()) for r in results.values()),
        "wall_seconds": round(time.perf_counter() - started, 1),
    }, file=args.out.name.removesuffix(".json"))


if __name__ == "__main__":
    main()
