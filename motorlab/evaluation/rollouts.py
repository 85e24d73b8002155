"""Batched evaluation rollouts: N episodes stepped side by side, one policy call
per time step for the whole batch (stateful controllers keep one row per episode).
The envs step in this process or in worker processes (`motorlab.evaluation.pool`);
the policy always acts here, so the results do not depend on where the envs live.

Returns are the task's own returns (reward shaping is for training only).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from motorlab.envs import EnvConfig, facts, max_return
from motorlab.envs.spaces import env_actions
from motorlab.errors import MotorlabError
from motorlab.evaluation.pool import SUCCESS_KEYS, EnvPool, auto_workers, make_pool, step_success
from motorlab.faults import fault_line
from motorlab.policies import Policy
from motorlab.runs import read_config

__all__ = ["SUCCESS_KEYS", "EpisodeSuccess", "Evaluator", "Rollouts", "evaluate", "step_success", "success_by",
           "success_mode", "trained_env_settings"]


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
    success_key: str | None = None  # the info key of the env's success flag (None: it has none)
    # episodes whose success is known: the env flagged it or the task has a maximum return (None: all)
    judged: np.ndarray | None = None

    @property
    def faults(self) -> int:
        """Episodes ended by a numerical fault (NaN/Inf, diverging simulation, a non-finite return)."""
        return len(self.fault_log)

    @property
    def success_rate(self) -> float | None:
        """The share of judged episodes that succeeded; None where success means nothing (an env
        with no success flag and no maximum return), never a 0% nobody measured."""
        judged = np.ones(len(self.success), bool) if self.judged is None else self.judged
        return float(np.mean(self.success[judged])) if judged.any() else None

    def summary(self) -> dict:
        """The headline numbers; non-finite returns (counted as faults) are left out of the return's
        statistics, so a blow-up is a counted fault, not "inf ± nan"."""
        r = self.returns[np.isfinite(self.returns)]
        return {
            "episodes": int(len(self.returns)),
            "return_mean": float(np.mean(r)) if len(r) else None,
            "return_std": float(np.std(r)) if len(r) else None,
            "return_min": float(np.min(r)) if len(r) else None,
            "return_max": float(np.max(r)) if len(r) else None,
            "success_rate": self.success_rate,
            "episode_length_mean": float(np.mean(self.lengths)) if len(self.lengths) else None,
            "episode_lengths": [int(x) for x in self.lengths],
            "falls": int(self.falls),
            "numerical_faults": int(self.faults),
        }


def success_mode(env_cfg: EnvConfig) -> str:
    """How episodes of this env count as successes: "any" step solved, or the "final" step.

    Args:
        env_cfg: its `success` setting; "auto" means the env's catalogue entry (motorlab.envs.catalog):
            "final" for MyoSuite's walking tasks, whose flag is a state a body falling forward also
            meets for a moment, and "any" for everything else (the SAR study's manipulation tasks).
    """
    if env_cfg.success != "auto":
        return env_cfg.success
    return facts(env_cfg.id).success_mode


def success_by(env_cfg: EnvConfig, key: str | None) -> str | None:
    """What counts as a successful episode of this env, in the words reports use: its own flag,
    the info `key` evaluation found (Rollouts.success_key), and when ('"solved" at the final
    step'); else reaching the task's maximum return ("return ≥ 1000"); else None (success means
    nothing here)."""
    if key is not None:
        return f'"{key}" at the final step' if success_mode(env_cfg) == "final" else f'"{key}" at any step'
    target = max_return(env_cfg.id)
    return None if target is None else f"return ≥ {target:g}"


class EpisodeSuccess:
    """Per-episode success for a batch of episodes, from the env's per-step flag:
    "solved at any step" (mode "any") or "solved at the last step" (mode "final").

    Envs without a success flag count an episode as a success when its return
    reaches the task's maximum (InvertedPendulum: 1000).
    """

    def __init__(self, n: int, target: float | None, mode: str = "any", keys: tuple[str, ...] = SUCCESS_KEYS):
        if mode not in ("any", "final"):
            raise ValueError(f"success mode {mode!r}: any or final")
        self.target = target
        self.keys = keys  # the info keys of the env's flag (its catalogue entry's success_keys)
        self.final = mode == "final"
        self.solved = np.zeros(n, dtype=bool)
        self.flagged = np.zeros(n, dtype=bool)

    def step(self, i: int, info: dict) -> None:
        self.flag(i, step_success(info, self.keys))

    def flag(self, i: int, flag: bool | None) -> None:
        """Row i's step reported `flag` (`step_success` of its info; None: no flag)."""
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
        workers: processes stepping the envs: this one and workers - 1 children (1: this one
            only, as training-time evaluation does); results are the same for any number.
    """

    def __init__(self, env_cfg: EnvConfig, episodes: int, seed: int, workers: int = 1):
        if workers < 1:
            raise MotorlabError(f"--workers must be at least 1, got {workers}.")
        self.env_cfg = env_cfg
        self.episodes = episodes
        self.seed = seed
        self.pool: EnvPool = make_pool(env_cfg, episodes, workers)
        self.workers = self.pool.workers  # processes used (1: this one)
        self.target = max_return(env_cfg.id)
        self.dt = self.pool.dt or 0.0

    @property
    def envs(self) -> list[gym.Env]:
        """The envs, where they live in this process (workers=1)."""
        envs = getattr(self.pool, "envs", None)
        if envs is None:
            raise AttributeError("the envs live in worker processes (workers > 1)")
        return envs

    @property
    def observation_space(self) -> gym.Space:
        return self.pool.observation_space

    @property
    def action_space(self) -> gym.Space:
        return self.pool.action_space

    def run(self, policy: Policy, stop_below: float | None = None, record: bool = False,
            first_seed: int | None = None, count: int | None = None) -> Rollouts:
        """Run `count` episodes (default: one per env), episode i from reset seed first_seed + i.

        Row r of the batch (env r) runs episodes r, r + R, r + 2R, ... (R envs), each starting as
        soon as the one before it ends, so the envs stay busy until the last episodes instead of
        waiting for the longest episode of every batch. Which row runs which episode does not depend
        on how the envs are spread over processes, so results are the same for any `workers`.
        A policy without `reset_row` (a row's state restarted alone) runs its episodes R at a time.

        Args:
            policy: acts on a batch of observations.
            stop_below: abort as soon as any episode ends with a return below this
                (used by --until-solved: one failure already means "not solved").
            record: keep observation and action traces.
            first_seed, count: episodes and the seed of the first (default: one per env, from the
                evaluator's seed).
        """
        n = self.episodes if count is None else count
        first = self.seed if first_seed is None else first_seed
        rows = min(n, self.episodes)
        if not hasattr(policy, "reset_row") and n > rows:
            parts = []
            for start in range(0, n, rows):
                parts.append(self.run(policy, stop_below, record, first + start, min(rows, n - start)))
                if parts[-1].aborted:
                    break
            return join_rollouts(parts)
        episode = np.arange(rows)  # the episode each row runs now
        obs = self.pool.reset([first + i for i in range(rows)])
        policy.reset(rows)
        active = np.ones(rows, dtype=bool)
        returns = np.zeros(n)
        lengths = np.zeros(n, dtype=int)
        success = np.zeros(n, dtype=bool)
        judged = np.zeros(n, dtype=bool)  # success known: a flag, or a maximum return to reach
        done = np.zeros(n, dtype=bool)
        outcome = EpisodeSuccess(rows, self.target, success_mode(self.env_cfg))
        key: str | None = None  # the env's success flag, once a step reports one
        falls = 0
        faults: list[tuple[int, str]] = []  # (episode, faults.log line): listed in episode order
        traces_o: list[list] = [[] for _ in range(n)] if record else []
        traces_a: list[list] = [[] for _ in range(n)] if record else []
        if record:
            for r in range(rows):
                traces_o[r].append(obs[r].copy())  # copies: obs rows are overwritten step by step
        while active.any():
            actions = env_actions(policy.act(obs), self.action_space)  # float32, or int64 action indices
            following = episode + rows  # each row's next episode, started by the env worker if this one ends
            restarts = np.where(following < n, first + following, -1)
            steps = self.pool.step(actions, active, restarts)
            for j, r in enumerate(steps.rows):
                i = episode[r]
                returns[i] += steps.reward[j]
                lengths[i] += 1
                outcome.flag(r, steps.flag(j))
                if key is None:
                    key = steps.flag_key(j, self.pool.success_keys)
                if record:
                    traces_o[i].append(steps.obs[j])
                    traces_a[i].append(actions[r])
                if not (steps.terminated[j] or steps.truncated[j]):
                    obs[r] = steps.obs[j]
                    continue
                done[i] = True
                result = outcome.end(r, returns[i])
                success[i], judged[i] = bool(result), result is not None
                fault = steps.fault.get(int(r)) or return_fault(returns[i])
                if fault:
                    faults.append((i, fault_line(first + i, lengths[i], fault)))
                falls += bool(steps.terminated[j]) and not fault
                if stop_below is not None and returns[i] < stop_below:
                    return Rollouts(returns[done], lengths[done], success[done], aborted=True,
                                    falls=falls, fault_log=[line for _, line in sorted(faults)], dt=self.dt,
                                    success_key=key, judged=judged[done])
                if steps.restarted[j]:
                    episode[r] = following[r]
                    obs[r] = steps.first_obs[j]
                    policy.reset_row(r)
                    if record:
                        traces_o[episode[r]].append(steps.first_obs[j].copy())
                else:
                    active[r] = False
        return Rollouts(
            returns, lengths, success, falls=falls, fault_log=[line for _, line in sorted(faults)], dt=self.dt,
            observations=[np.array(t) for t in traces_o], actions=[np.array(t) for t in traces_a],
            success_key=key, judged=judged,
        )

    def close(self) -> None:
        self.pool.close()

    def __enter__(self) -> Evaluator:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.pool.__exit__(*exc)


def evaluate(policy: Policy, env_cfg: EnvConfig, episodes: int, seed: int, record: bool = False,
             batch: int = 50, workers: int | None = None) -> Rollouts:
    """Evaluate `policy` for `episodes` episodes on the env `env_cfg` describes.

    Episodes run on `batch` envs, each env running its share one after another (episode i
    always starts from seed + i; see `Evaluator.run`), so hundreds of episodes of a large model
    neither hold nor build hundreds of envs. The envs step in `workers` processes, this one and
    workers - 1 children (None: every core when the work is large enough to pay for starting
    them, see `pool.auto_workers`; 1: this process only); the policy acts in this process on the
    same batches either way, so the results are the same, number for number.

    Raises:
        MotorlabError: workers < 1 (from Evaluator); an env worker that failed or died (one line).
    """
    with open_evaluator(env_cfg, episodes, seed, workers, batch) as ev:
        return ev.run(policy, record=record, first_seed=seed, count=episodes)


def open_evaluator(env_cfg: EnvConfig, episodes: int, seed: int, workers: int | None, batch: int = 50,
                   work: int | None = None) -> Evaluator:
    """The Evaluator `evaluate` plays `episodes` episodes on: min(batch, episodes) envs in `workers` processes
    (None: `pool.auto_workers` for `work` episodes in all, default `episodes`).

    Raises:
        MotorlabError: workers < 1; an env the workers cannot build when `workers` was given."""
    size = min(batch, episodes)
    n = auto_workers(env_cfg, work or episodes, size) if workers is None else workers
    try:
        return Evaluator(env_cfg, size, seed, workers=n)
    except MotorlabError:
        if workers is not None or n == 1:
            raise
        # auto: an env the workers cannot build (registered only in this process, not by a module
        # they import) still evaluates here; a real error is raised again by the serial pool
        return Evaluator(env_cfg, size, seed, workers=1)


def join_rollouts(parts: list[Rollouts]) -> Rollouts:
    """Consecutive parts of one evaluation as one."""
    if len(parts) == 1:
        return parts[0]
    return Rollouts(np.concatenate([p.returns for p in parts]), np.concatenate([p.lengths for p in parts]),
                    np.concatenate([p.success for p in parts]), aborted=any(p.aborted for p in parts),
                    falls=sum(p.falls for p in parts), fault_log=[line for p in parts for line in p.fault_log],
                    observations=[o for p in parts for o in p.observations],
                    actions=[a for p in parts for a in p.actions], dt=parts[0].dt,
                    success_key=next((p.success_key for p in parts if p.success_key), None),
                    judged=np.concatenate([np.ones(len(p.success), bool) if p.judged is None else p.judged
                                           for p in parts]))


def return_fault(ret: float) -> str | None:
    """A numerical fault of an episode whose return is not a finite number (rewards that each
    passed the guard but whose sum overflowed): counted and logged like the guard's faults."""
    return None if np.isfinite(ret) else f"non-finite return ({ret}): the rewards' sum left the float range"


def trained_env_settings(run_dir: Path) -> dict:
    """The env settings a run folder records, without reward shaping: evaluation,
    plots, videos, collection and zero-shot all report the task's own return."""
    return {k: v for k, v in read_config(run_dir).get("env", {}).items() if k != "reward"}
