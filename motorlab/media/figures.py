"""`motorlab plot RUN_DIR`: the figures of one run folder (its policy rolled out, drawn with
motorlab.report.plots)."""

from __future__ import annotations

from pathlib import Path

from motorlab.envs import EnvConfig, make_env
from motorlab.evaluation import evaluate, trained_env_settings
from motorlab.policies import load_policy
from motorlab.report.plots import env_tag, obs_labels, observation_trace, plot_learning_curve
from motorlab.runs import read_config, require_run_dir, wrote_into

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
        title=f"{env_cfg.id}{env_tag(env_cfg.model_dump())}: return {result.returns[0]:.0f}")] if p is not None]
    wrote_into(run_dir)  # the finished run's marker lists them: an --overwrite replaces them with it
    return written
