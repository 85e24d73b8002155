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

from motorlab.dynamics.collect import collect_transitions
from motorlab.dynamics.model import ForwardModel, load_model
from motorlab.dynamics.state import xy_columns
from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_npz, prepare_run_dir, write_config, write_summary

REPORT_STEPS = (1, 5, 10, 25)


def open_loop(model: ForwardModel, episodes: int, seed: int = 0, steps: int | None = None) -> dict[str, np.ndarray]:
    """Simulator and model states (E, T+1, S) under the same random actions (E, T, A), and goals (E, G).

    The simulator side is `collect_transitions` on Gymnasium's env (episode k from seed + k), so the
    check sees exactly what `dynamics collect --simulator gymnasium` would record.
    """
    data = collect_transitions(model.meta["env_id"], episodes, workers=1, seed=seed,
                               state=model.meta["state_layout"], simulator="gymnasium", progress=False)
    rows = [np.flatnonzero(data.episode == e) for e in range(episodes)]
    # an episode may terminate early: compare the common length
    horizon = min(min(len(r) for r in rows), steps or np.inf)
    rows = np.stack([r[:horizon] for r in rows])  # (E, T)
    true = np.concatenate([data.states[rows[:, :1]], data.next_states[rows]], axis=1)
    actions = data.actions[rows]
    s = torch.as_tensor(true[:, 0], dtype=torch.float32)
    predicted = [s]
    with torch.no_grad():
        for t in range(horizon):
            s = model.predict(s, torch.as_tensor(actions[:, t], dtype=torch.float32))
            predicted.append(s)
    return {"true": true, "model": torch.stack(predicted, 1).numpy().astype(np.float64), "actions": actions,
            "goals": data.goals[rows[:, 0]]}


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
    xy = xy_columns(labels)
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
