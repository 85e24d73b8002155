"""Model-based control from Python: MPC on a learned forward model, and the PETS loop."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab.api import running
from motorlab.api.checks import api_function
from motorlab.api.running import Track
from motorlab.api.views import Result
from motorlab.kinds.planning import MBRL, MPC


@api_function
def mpc(env: str, model: str | Path | Result, *, episodes: int | None = None, out: str | Path | None = None,
        progress: bool = True, track: Track = None, **settings: Any) -> Result:
    """Model-predictive control of `env` on a learned forward model (`motorlab mpc`).

    Args:
        env: the env id the model was fit on (Reacher-v5, or MODULE:ID).
        model: a `motorlab.dynamics.fit` result or a model folder.
        episodes: control episodes (default 50).
        **settings: optimizer ("cem", "mppi", "evotorch"), horizon, population, iterations, elites,
            reward ("auto", a builtin, MODULE:FUNCTION or "learned"), parallel, video, ...; and the
            env's settings (the ones the model was fit under): history, delay, obs_noise, sar, env_kwargs, ...

    Returns:
        Its numbers (`["return_mean"]`, `["success_rate"]`, `["plan_ms_median"]`) and plots.
    """
    return running.run_kind(MPC, out, progress, track, env=env, model=model, episodes=episodes, **settings)


@api_function
def mbrl(env: str, rounds: int | None = None, *, out: str | Path | None = None, progress: bool = True,
         track: Track = None, **settings: Any) -> Result:
    """The model-based RL loop (PETS, `motorlab mbrl`): plan with the ensemble, collect, refit, evaluate.

    Args:
        env: any Box-action env (InvertedPendulum-v5, MODULE:ID).
        rounds: collect-fit-evaluate rounds (default 10).
        **settings: ensemble, probabilistic, propagation, horizon, population, episodes_per_round,
            eval_episodes, until_return, ...; and the env's settings: delay, history, obs_noise,
            push_body, sar, env_kwargs, ... (the loop collects from, and plans in, the env they make).

    Returns:
        Its folder: curve.csv, plots/learning_curve.png, the final model in model/.
    """
    return running.run_kind(MBRL, out, progress, track, env=env, rounds=rounds, **settings)
