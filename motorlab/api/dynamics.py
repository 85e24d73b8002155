"""Forward models from Python (`motorlab dynamics ...`): collect transitions, fit, check open loop.

```python
data = motorlab.api.dynamics.collect("Reacher-v5", episodes=2000)
model = motorlab.api.dynamics.fit(data, epochs=50)
motorlab.api.dynamics.check(model)                    # error vs horizon against the simulator
motorlab.mpc("Reacher-v5", model, episodes=20)
```
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab.api import running
from motorlab.api.checks import api_function
from motorlab.api.running import Track
from motorlab.api.views import Result
from motorlab.kinds.dynamics import DYNAMICS_CHECK, DYNAMICS_COLLECT, DYNAMICS_FIT

__all__ = ["collect", "fit", "check"]


@api_function
def collect(env: str, episodes: int | None = None, *, out: str | Path | None = None, progress: bool = True,
            **settings: Any) -> Result:
    """Record transitions (state, action, next state, reward, done) to transitions.npz.

    Args:
        env: the env id (Reacher-v5, or MODULE:ID).
        episodes: episodes to record (default 1,000).
        **settings: policy ("random", or a run), simulator ("auto", "closed-form", "mujoco", "gymnasium"),
            state, workers, seed; and the env's settings, as every env-building command takes them:
            delay, history, obs_noise, latency, push_body, sar, env_kwargs={...}, reward, ...
    """
    return running.run_kind(DYNAMICS_COLLECT, out, progress, env=env, episodes=episodes, **settings)


@api_function
def fit(transitions: str | Path | Result, *, epochs: int | None = None, out: str | Path | None = None,
        progress: bool = True, track: Track = None, **settings: Any) -> Result:
    """Fit a forward model of the normalized state delta: model.safetensors + model.json.

    Args:
        transitions: a `collect` result, its folder or transitions.npz.
        epochs: training epochs (default: 50, or more on little data, enough for 4,000 gradient steps).
        **settings: hidden (default [200, 200]), lr, batch_size, ensemble, probabilistic, learn_reward,
            learn_termination, patience, valid_fraction, seed.
    """
    return running.run_kind(DYNAMICS_FIT, out, progress, track, transitions=transitions, epochs=epochs, **settings)


@api_function
def check(model: str | Path | Result, *, episodes: int | None = None, out: str | Path | None = None,
          progress: bool = True, **settings: Any) -> Result:
    """The model against the simulator under the same actions, open loop: error vs horizon,
    traces, and the summary numbers (`motorlab dynamics check`)."""
    return running.run_kind(DYNAMICS_CHECK, out, progress, model=model, episodes=episodes, **settings)
