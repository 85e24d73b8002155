"""LQR: motorlab's model-based learner (controllers/lqr.py), not an SB3 algorithm.

A least-squares linear model of the dynamics, refitted as steps come in, and the LQR gain on it;
NumPy and SciPy only, so an LQR run starts without torch. It is an `Algorithm` (a name, presets,
the actions it fits, its settings checks) but neither on- nor off-policy in SB3's sense: it takes
no hyperparameters, checkpoints or ONNX export (its policy is a gain matrix in policy.json).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from motorlab.algos.base import Algorithm, Preset
from motorlab.errors import MotorlabError


@dataclass(frozen=True)
class LQR(Algorithm):
    """Trains itself (train.py calls `learn`): no SB3 model, no checkpoint."""

    def learn(self, cfg: Any, run_dir: Path, monitor: Any) -> int:
        """Fit, control and evaluate to the budget; write policy.json. Returns env steps used.

        `monitor` is the run's rl.monitor.TrainingMonitor, which sits above this registry (it
        evaluates policies, which the registry's algorithms load)."""
        from rich.progress import Progress

        from motorlab.controllers import save_controller
        from motorlab.controllers.lqr import learn_lqr

        stop = {"solved": False}

        def on_update(steps, policy, info):
            monitor.tb.add_scalar("model/one_step_mse", info["model_mse"], steps)
            if steps - max(monitor.last_eval_steps, 0) >= (cfg.eval_every or 0) or not cfg.eval_every:
                stop["solved"] = monitor.evaluate(steps, policy)
            return cfg.until_solved and stop["solved"]

        with Progress(disable=not cfg.progress, transient=True) as bar:
            task = bar.add_task(f"lqr on {cfg.env.id}", total=cfg.timesteps)
            policy, steps = learn_lqr(cfg.env, cfg.lqr, cfg.timesteps, cfg.seed, on_update,
                                      on_episode=monitor.episode, on_steps=lambda s: bar.update(task, completed=s))
        if policy is None:
            raise MotorlabError(f"no linear model could be fitted in {steps} steps; raise --timesteps.")
        if monitor.last_eval_steps < steps:
            monitor.evaluate(steps, policy)
        save_controller(run_dir, policy)
        return steps


ALGORITHM = LQR(
    name="lqr",
    title="LQR",
    summary="model-based: a least-squares linear model + LQR, refitted every 100 steps; Box actions",
    eval_cadence="each LQR refit",
    bounded_actions=True,  # its controller clips to the action bounds, and acts on one vector of them
    vector_actions=True,
    presets={
        # motorlab's most sample-efficient configuration for balance/regulation tasks:
        # least-squares linear model + LQR, refitted every 100 steps (see controllers/lqr.py).
        # InvertedPendulum: ~100 env steps plain, ~100-300 with 0.2 s actuation + perception delay.
        "fast": Preset("linear model + LQR, refitted every 100 steps: the most sample-efficient on balance tasks",
                       {"lqr": {}}),
    },
)
