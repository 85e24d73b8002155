"""Zero-shot transfer: trained policies on envs they never saw (e.g. new objects).

Each run's policy acts on each listed env, built like the run's own env (delay,
history, synergy actions) with only the id changed. Success is the env's
"solved at any step" (MyoSuite's info["solved"]).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from motorlab.envs import EnvConfig, check_env_id
from motorlab.errors import MotorlabError
from motorlab.evaluation.pool import keep_workers
from motorlab.evaluation.rollouts import evaluate, trained_env_settings
from motorlab.policies import load_run_policy
from motorlab.runs import require_run_dir


@dataclass
class Transfer:
    """Every run on every env: `results[run][env]` is that evaluation's summary."""

    names: list[str]  # the runs as tables and summary keys name them
    envs: list[str]
    results: dict[str, dict[str, dict]]
    fault_log: list[str]


def run_label(run: Path) -> str:
    """A run's name in tables: its folder, or "<step>/seed<k>" for one seed of several."""
    return f"{run.parent.name}/{run.name}" if re.fullmatch(r"seed\d+", run.name) else run.name


def transfer(run_dirs: list[Path], envs: list[str], episodes: int = 500, seed: int = 0,
             workers: int | None = None, before_work: Callable[[], None] | None = None) -> Transfer:
    """Evaluate every run's policy on every env, `episodes` episodes each from `seed`, the envs
    stepping in `workers` processes (see `evaluate`; the results do not depend on it).
    `before_work` is called once the runs and envs are checked, before the first episode (`transfer`
    refuses a finished --out there).

    Raises:
        MotorlabError: no runs or envs, unknown env id, a policy whose action or
            observation size does not fit an env.
    """
    if not run_dirs or not envs:
        raise MotorlabError("give at least one run folder and one env (--envs ID ...).")
    if episodes <= 0:
        raise MotorlabError(f"--episodes must be positive, got {episodes}.")
    if workers is not None and workers < 1:
        raise MotorlabError(f"--workers must be at least 1, got {workers}.")
    for env_id in envs:
        check_env_id(env_id)
    runs = [require_run_dir(Path(r)) for r in run_dirs]
    names = [run_label(r) for r in runs]
    if len(set(names)) < len(names):
        names = [str(r) for r in runs]
    if before_work is not None:
        before_work()
    results: dict[str, dict[str, dict]] = {}
    fault_log: list[str] = []
    with keep_workers():  # every evaluation below steps its envs in the same worker processes
        for name, run in zip(names, runs, strict=True):
            base = trained_env_settings(run)
            policy = load_run_policy(run)
            results[name] = {}
            for env_id in envs:
                cfg = EnvConfig.model_validate({**base, "id": env_id})
                rollouts = evaluate(policy, cfg, episodes, seed, workers=workers)
                results[name][env_id] = rollouts.summary()
                fault_log += [f"{name} on {env_id}: {line}" for line in rollouts.fault_log]
    return Transfer(names, list(envs), results, fault_log)
