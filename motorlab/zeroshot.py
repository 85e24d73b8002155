"""`motorlab zeroshot`: trained policies on envs they never saw (e.g. new objects).

Each run's policy acts on each listed env, built like the run's own env (delay,
history, synergy actions) with only the id changed. Success is the env's
"solved at any step" (MyoSuite's info["solved"]).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from motorlab.envs import EnvConfig, check_env_id
from motorlab.evaluate import evaluate, trained_env_settings
from motorlab.faults import write_faults_log
from motorlab.errors import MotorlabError
from motorlab.policies import load_run_policy
from motorlab.report.plots import grouped_bars
from motorlab.runs import prepare_run_dir, require_run_dir, write_config, write_summary


def zeroshot(run_dirs: list[Path], envs: list[str], episodes: int = 500, seed: int = 0,
             out: Path | None = None, console: Console | None = None,
             labels: list[str] | None = None) -> dict[str, Any]:
    """Evaluate every run on every env; write summary.json, table.txt and zeroshot.png.

    Returns:
        Flat summary: "<run>.<env>.success_rate", "<run>.<env>.return_mean", ...

    Raises:
        MotorlabError: no runs or envs, unknown env id, a policy whose action or
            observation size does not fit an env.
    """
    if not run_dirs or not envs:
        raise MotorlabError("give at least one run folder and one env (--envs ID ...).")
    if episodes <= 0:
        raise MotorlabError(f"--episodes must be positive, got {episodes}.")
    for env_id in envs:
        check_env_id(env_id)
    runs = [require_run_dir(Path(r)) for r in run_dirs]
    names = list(labels) if labels else [r.name for r in runs]
    if len(set(names)) < len(names):
        names = [str(r) for r in runs]
    results: dict[str, dict[str, dict]] = {}
    fault_log: list[str] = []
    for name, run in zip(names, runs):
        base = trained_env_settings(run)
        policy = load_run_policy(run)
        results[name] = {}
        for env_id in envs:
            cfg = EnvConfig.model_validate({**base, "id": env_id})
            rollouts = evaluate(policy, cfg, episodes, seed)
            results[name][env_id] = rollouts.summary()
            fault_log += [f"{name} on {env_id}: {line}" for line in rollouts.fault_log]
    out_dir = prepare_run_dir(out, "zeroshot")
    write_config(out_dir, {"runs": [str(r) for r in runs], "envs": envs, "episodes": episodes, "seed": seed})
    grouped_bars(envs, {n: [results[n][e]["success_rate"] for e in envs] for n in names}, "success rate",
                 out_dir / "plots" / "zeroshot.png", f"Zero-shot success ({episodes} episodes per env)",
                 percent=True)
    table = Table(title=f"zero-shot: {episodes} episodes per env, seed {seed}")
    table.add_column("run")
    for env_id in envs:
        table.add_column(f"{env_id} success", justify="right")
        table.add_column("return", justify="right")
    for n in names:
        row = [n]
        for env_id in envs:
            r = results[n][env_id]
            row += [f"{r['success_rate']:.1%}", f"{r['return_mean']:.1f}"]
        table.add_row(*row)
    (console or Console()).print(table)
    summary: dict[str, Any] = {"runs": names, "envs": envs, "episodes": episodes, "seed": seed}
    for n in names:
        for env_id in envs:
            r = results[n][env_id]
            for key in ("success_rate", "return_mean", "return_std", "numerical_faults"):
                summary[f"{n}.{env_id}.{key}"] = r[key]
    summary["numerical_faults"] = len(fault_log)
    write_faults_log(out_dir, fault_log)
    write_summary(out_dir, summary)
    summary["run_dir"] = str(out_dir)
    return summary
