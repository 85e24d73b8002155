"""Batched evaluation rollouts: N episodes stepped side by side, one policy call
per time step for the whole batch (stateful controllers keep one row per episode).

Returns are the task's own returns (reward shaping is for training only).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np

from motorlab.envs import EnvConfig, env_dt, make_env, max_return
from motorlab.faults import fault_line, fault_of
from motorlab.policies import Policy
from motorlab.runs import read_config


@dataclass
class Rollouts:
    """Outcome of evaluation episodes (aborted episodes are not included)."""

    returns: np.ndarray
    lengths: np.ndarray
    success: np.ndarray
    aborted: bool = False
    falls: int = 0  # episodes the env terminated before the time limit (a fall, for balancing tasks)
    fault_log: list[str] = field(default_factory=list)  # one line per faulted episode: its seed and reason
    observations: list[np.ndarray] = field(default_factory=list)  # per episode, when recorded
    actions: list[np.ndarray] = field(default_factory=list)
    dt: float = 0.0

    @property
    def faults(self) -> int:
        """Episodes ended by a numerical fault (NaN/Inf, diverging simulation)."""
        return len(self.fault_log)

    def summary(self) -> dict:
        r = self.returns
        return {
            "episodes": int(len(r)),
            "return_mean": float(np.mean(r)) if len(r) else None,
            "return_std": float(np.std(r)) if len(r) else None,
            "return_min": float(np.min(r)) if len(r) else None,
            "return_max": float(np.max(r)) if len(r) else None,
            "success_rate": float(np.mean(self.success)) if len(r) else None,
            "episode_length_mean": float(np.mean(self.lengths)) if len(r) else None,
            "episode_lengths": [int(x) for x in self.lengths],
            "falls": int(self.falls),
            "numerical_faults": int(self.faults),
        }


SUCCESS_KEYS = ("solved", "success", "is_success")


def step_success(info: dict) -> bool | None:
    """The env's own success flag for this step (MyoSuite: info["solved"]), or None."""
    for key in SUCCESS_KEYS:
        if key in info:
            return bool(info[key])
    return None


# MyoSuite's walking tasks (myoLegWalk-v0, myoLeg{Hilly,Rough,Stair}TerrainWalk-v0): their
# "solved" is "upright and within 0.5 m/s of the commanded speed" at that step, which a body
# falling forward also meets for a moment before it is counted as fallen.
_STATE_SUCCESS_IDS = re.compile(r"^myoLeg.*Walk")


def success_mode(env_cfg: EnvConfig) -> str:
    """How episodes of this env count as successes: "any" step solved, or the "final" step.

    Args:
        env_cfg: its `success` setting; "auto" means "final" for MyoSuite's walking tasks
            and "any" for everything else (the SAR study's manipulation tasks).
    """
    if env_cfg.success != "auto":
        return env_cfg.success
    return "final" if _STATE_SUCCESS_IDS.match(env_cfg.id) else "any"


class EpisodeSuccess:
    """Per-episode success for a batch of episodes, from the env's per-step flag:
    "solved at any step" (mode "any") or "solved at the last step" (mode "final").

    Envs without a success flag count an episode as a success when its return
    reaches the task's maximum (InvertedPendulum: 1000).
    """

    def __init__(self, n: int, target: float | None, mode: str = "any"):
        if mode not in ("any", "final"):
            raise ValueError(f"success mode {mode!r}: any or final")
        self.target = target
        self.final = mode == "final"
        self.solved = np.zeros(n, dtype=bool)
        self.flagged = np.zeros(n, dtype=bool)

    def step(self, i: int, info: dict) -> None:
        flag = step_success(info)
        if flag is not None:
            self.flagged[i] = True
            self.solved[i] = flag if self.final else self.solved[i] | flag

    def end(self, i: int, ret: float) -> bool | None:
        """Outcome of row i's finished episode (None: unknowable), and restart the row."""
        if self.flagged[i]:
            result = bool(self.solved[i])
        else:
            result = None if self.target is None else bool(ret >= self.target)
        self.solved[i] = self.flagged[i] = False
        return result


class Evaluator:
    """Holds `episodes` envs for repeated evaluation (e.g. during training).

    Args:
        env_cfg: the env and wrappers the policy was made for.
        episodes: episodes per evaluation, run as one batch.
        seed: episode i starts from reset(seed=seed + i), so evaluations repeat exactly.
    """

    def __init__(self, env_cfg: EnvConfig, episodes: int, seed: int):
        self.env_cfg = env_cfg
        self.episodes = episodes
        self.seed = seed
        self.envs = [make_env(env_cfg, shaped=False) for _ in range(episodes)]
        self.target = max_return(env_cfg.id)
        self.dt = env_dt(self.envs[0]) or 0.0

    @property
    def observation_space(self) -> gym.Space:
        return self.envs[0].observation_space

    @property
    def action_space(self) -> gym.Space:
        return self.envs[0].action_space

    def run(self, policy: Policy, stop_below: float | None = None, record: bool = False,
            first_seed: int | None = None, count: int | None = None) -> Rollouts:
        """Run one episode per env.

        Args:
            policy: acts on a batch of observations.
            stop_below: abort as soon as any episode ends with a return below this
                (used by --until-solved: one failure already means "not solved").
            record: keep observation and action traces.
            first_seed, count: run only the first `count` envs, episode i from
                first_seed + i (default: all envs from the evaluator's seed).
        """
        n = self.episodes if count is None else count
        first = self.seed if first_seed is None else first_seed
        envs = self.envs[:n]
        obs = np.stack([env.reset(seed=first + i)[0] for i, env in enumerate(envs)])
        policy.reset(n)
        active = np.ones(n, dtype=bool)
        returns = np.zeros(n)
        lengths = np.zeros(n, dtype=int)
        success = np.zeros(n, dtype=bool)
        outcome = EpisodeSuccess(n, self.target, success_mode(self.env_cfg))
        falls = 0
        fault_log: list[str] = []
        traces_o = [[o] for o in obs] if record else []
        traces_a: list[list] = [[] for _ in range(n)] if record else []
        while active.any():
            actions = np.asarray(policy.act(obs), dtype=np.float32)
            for i in np.flatnonzero(active):
                o, r, terminated, truncated, info = envs[i].step(actions[i])
                obs[i] = o
                returns[i] += r
                lengths[i] += 1
                outcome.step(i, info)
                if record:
                    traces_o[i].append(o)
                    traces_a[i].append(actions[i])
                if terminated or truncated:
                    active[i] = False
                    success[i] = bool(outcome.end(i, returns[i]))
                    fault = fault_of(info)
                    if fault:
                        fault_log.append(fault_line(first + i, lengths[i], fault))
                    falls += bool(terminated) and not fault
                    if stop_below is not None and returns[i] < stop_below:
                        done = ~active
                        return Rollouts(returns[done], lengths[done], success[done], aborted=True,
                                        falls=falls, fault_log=fault_log, dt=self.dt)
        return Rollouts(
            returns, lengths, success, falls=falls, fault_log=fault_log, dt=self.dt,
            observations=[np.array(t) for t in traces_o], actions=[np.array(t) for t in traces_a],
        )

    def close(self) -> None:
        for env in self.envs:
            env.close()


def evaluate(policy: Policy, env_cfg: EnvConfig, episodes: int, seed: int, record: bool = False,
             batch: int = 50) -> Rollouts:
    """Evaluate `policy` for `episodes` episodes on the env `env_cfg` describes.

    Episodes run `batch` at a time on the same `batch` envs (episode i always
    starts from seed + i), so hundreds of episodes of a large model neither hold
    nor build hundreds of envs.
    """
    ev = Evaluator(env_cfg, min(batch, episodes), seed)  # envs are made once and reused batch after batch
    try:
        parts = [ev.run(policy, record=record, first_seed=seed + start, count=min(batch, episodes - start))
                 for start in range(0, episodes, batch)]
    finally:
        ev.close()
    if len(parts) == 1:
        return parts[0]
    return Rollouts(np.concatenate([p.returns for p in parts]), np.concatenate([p.lengths for p in parts]),
                    np.concatenate([p.success for p in parts]),
                    falls=sum(p.falls for p in parts), fault_log=[line for p in parts for line in p.fault_log],
                    observations=[o for p in parts for o in p.observations],
                    actions=[a for p in parts for a in p.actions], dt=parts[0].dt)


def trained_env_settings(run_dir: Path) -> dict:
    """The env settings a run folder records, without reward shaping: evaluation,
    plots, videos, collection and zero-shot all report the task's own return."""
    return {k: v for k, v in read_config(run_dir).get("env", {}).items() if k != "reward"}
