"""`motorlab dynamics check`: the model vs the simulator over open-loop rollouts.

From the same initial state and under the same random actions, Gymnasium's env and the
model (fed its own predictions) each roll out an episode. The error at each step ahead
shows how far the model can be trusted as a planner's horizon.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from motorlab.dynamics.model import ForwardModel, load_model
from motorlab.dynamics.state import layout_for
from motorlab.envs import EnvConfig, make_env
from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_npz, prepare_run_dir, write_config, write_summary

REPORT_STEPS = (1, 5, 10, 25)


def open_loop(model: ForwardModel, episodes: int, seed: int = 0, steps: int | None = None) -> dict[str, np.ndarray]:
    """Simulator and model states (E, T+1, S) under the same random actions (E, T, A), and goals (E, G)."""
    env_id = model.meta["env_id"]
    env = make_env(EnvConfig(id=env_id), shaped=False)
    layout = layout_for(env_id, env.observation_space.shape[0], model.meta["state_layout"])
    steps = steps or env.spec.max_episode_steps or 100
    true, pred, acts, goals = [], [], [], []
    for e in range(episodes):
        rng = np.random.default_rng(seed + e)
        obs, _ = env.reset(seed=seed + e)
        goals.append(layout.goal(obs))
        states, actions = [layout.state(obs)], []
        for _ in range(steps):
            a = rng.uniform(env.action_space.low, env.action_space.high)
            obs, _, terminated, *_ = env.step(a)
            states.append(layout.state(obs))
            actions.append(a)
            if terminated:
                break
        s = torch.as_tensor(states[0], dtype=torch.float32)[None]
        model_states = [s[0]]
        with torch.no_grad():
            for a in actions:
                s = model.predict(s, torch.as_tensor(a, dtype=torch.float32)[None])
                model_states.append(s[0])
        true.append(np.array(states))
        pred.append(torch.stack(model_states).numpy().astype(np.float64))
        acts.append(np.array(actions))
    env.close()
    horizon = min(len(t) for t in true)  # an episode may terminate early: compare the common length
    return {"true": np.stack([t[:horizon] for t in true]), "model": np.stack([p[:horizon] for p in pred]),
            "actions": np.stack([a[:horizon - 1] for a in acts]), "goals": np.stack(goals)}


def _xy_columns(labels: list[str]) -> list[int] | None:
    cols = [labels.index(k) for k in ("tip x", "tip y") if k in labels]
    return cols if len(cols) == 2 else None


def check_step(model_path: Path, episodes: int = 5, seed: int = 0, steps: int | None = None,
               out: Path | None = None) -> dict[str, Any]:
    """Open-loop check of a forward model: error vs horizon plot, x-y traces, summary.json, rollouts.npz."""
    from motorlab.report.dynamics_plots import error_vs_horizon, xy_traces

    if episodes <= 0:
        raise MotorlabError(f"--episodes must be positive, got {episodes}.")
    if steps is not None and steps <= 0:
        raise MotorlabError(f"--steps must be positive, got {steps}.")
    model = load_model(model_path)
    r = open_loop(model, episodes, seed, steps)
    run = prepare_run_dir(out, "dynamics-check")
    labels = list(model.meta.get("state_labels") or [])
    scale = model.state_norm.std.numpy()  # state errors in units of each entry's spread in the data
    diff = r["model"] - r["true"]
    nrmse = np.sqrt(((diff / scale) ** 2).mean(-1))  # (E, T+1)
    horizons = np.arange(diff.shape[1])
    errors = {"state (normalized RMSE)": nrmse}
    summary: dict[str, Any] = {"env_id": model.meta["env_id"], "episodes": episodes, "horizon": int(horizons[-1])}
    xy = _xy_columns(labels)
    if xy:
        tip = np.linalg.norm(diff[..., xy], axis=-1)
        for h in REPORT_STEPS:
            if h <= horizons[-1]:
                summary[f"tip_error_mean_h{h}"] = float(tip[:, h].mean())
        summary["tip_error_mean_final"] = float(tip[:, -1].mean())
        error_vs_horizon(horizons, {"fingertip": tip * 1000}, run / "plots" / "tip_error.png",
                         f"{model.meta['env_id']}: open-loop fingertip error", "fingertip error (mm)")
    for h in REPORT_STEPS:
        if h <= horizons[-1]:
            summary[f"state_nrmse_h{h}"] = float(nrmse[:, h].mean())
    summary["state_nrmse_final"] = float(nrmse[:, -1].mean())
    error_vs_horizon(horizons, errors, run / "plots" / "error_vs_horizon.png",
                     f"{model.meta['env_id']}: model vs simulator, open loop", "normalized RMSE")
    cols = xy or [0, 1]
    names = tuple(labels[c] if labels else f"state[{c}]" for c in cols)
    xy_traces(r["true"][..., cols], r["model"][..., cols], r["goals"] if xy else None,
              run / "plots" / "traces.png", f"{model.meta['env_id']}: simulator vs model, {episodes} episodes",
              tuple(n + (" (m)" if xy else "") for n in names))
    atomic_write_npz(run / "rollouts.npz", **r)
    write_config(run, {"model": str(model_path), "episodes": episodes, "seed": seed, "steps": steps})
    write_summary(run, summary)
    summary["run_dir"] = str(run)
    return summary
