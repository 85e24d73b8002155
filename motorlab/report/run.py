"""`motorlab plot RUN_DIR`: the figures of one run folder."""

from __future__ import annotations

from pathlib import Path

from motorlab.envs import EnvConfig, make_env
from motorlab.evaluation import evaluate, trained_env_settings
from motorlab.policies import load_policy
from motorlab.report.plots import learning_curve, obs_labels, observation_trace
from motorlab.runs import METRICS, read_config, read_json, require_run_dir

TRACE_SEED = 123  # a fixed episode, so re-plotting gives the same figure


def plot_run(run_dir: Path) -> list[Path]:
    """Write plots/learning_curve.png (training runs) and plots/observation_trace.png.

    The trace is one deterministic episode of the run's policy on the env it was
    trained (or evaluated) on; with observation history, the newest frame is shown.

    Returns:
        The PNG files written.
    """
    run_dir = require_run_dir(Path(run_dir))
    config = read_config(run_dir)
    plots = run_dir / "plots"
    written = [p for p in [plot_learning_curve(run_dir)] if p is not None]
    env_cfg = EnvConfig.model_validate(trained_env_settings(run_dir))
    spec = config.get("policy", str(run_dir))

    probe = make_env(env_cfg)
    policy = load_policy(spec, probe, env_cfg.id)
    probe.close()
    result = evaluate(policy, env_cfg, episodes=1, seed=TRACE_SEED, record=True)
    obs = result.observations[0]
    base_dim = obs.shape[1] // env_cfg.history
    obs = obs[:, -base_dim:]  # newest frame of the history
    written += [p for p in [observation_trace(
        obs, result.actions[0], result.dt, obs_labels(env_cfg.id, base_dim), plots / "observation_trace.png",
        title=f"{env_cfg.id}{_env_tag(env_cfg.model_dump())}: return {result.returns[0]:.0f}")] if p is not None]
    return written


def plot_learning_curve(run_dir: Path) -> Path | None:
    """plots/learning_curve.png of a training run (None for runs without metrics.csv)."""
    if not (Path(run_dir) / METRICS).is_file():
        return None
    config = read_config(run_dir)
    summary = read_json(Path(run_dir) / "summary.json")
    return learning_curve(run_dir, Path(run_dir) / "plots" / "learning_curve.png",
                          title=f"{summary.get('algo', '').upper()} on {summary.get('env_id')}"
                                f"{_env_tag(config.get('env', {}))} (seed {summary.get('seed')})",
                          solve_return=summary.get("solve_return"), steps_to_success=summary.get("steps_to_success"))


def _env_tag(env: dict) -> str:
    parts = []
    if env.get("delay"):
        parts.append(f"delay {env['delay']} s on {env.get('delay_on', 'action')}")
    if env.get("history", 1) > 1:
        parts.append(f"history {env['history']}")
    return f" ({', '.join(parts)})" if parts else ""
