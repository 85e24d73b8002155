"""`motorlab dynamics check`: the model vs the simulator over open-loop rollouts.

From the same initial state and under the same random actions, Gymnasium's env and the
model (fed its own predictions) each roll out an episode. The error at each step ahead
shows how far the model can be trusted as a planner's horizon.
"""

from __future__ import annotations

import numpy as np
import torch

from motorlab.dynamics.collect import collect_transitions
from motorlab.dynamics.model import ForwardModel

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
