"""`motorlab dynamics check`: the model vs the simulator over open-loop rollouts.

From the same initial state and under the same random actions, Gymnasium's env and the
model (fed its own predictions) each roll out an episode. The error at each step ahead
shows how far the model can be trusted as a planner's horizon.
"""

from __future__ import annotations

import numpy as np
import torch

from motorlab.dynamics.collection import collect_transitions
from motorlab.dynamics.model import ForwardModel
from motorlab.envs import EnvConfig

REPORT_STEPS = (1, 5, 10, 25)


def open_loop(model: ForwardModel, episodes: int, seed: int = 0, steps: int | None = None) -> dict[str, np.ndarray]:
    """Simulator and model states (E, T+1, S) under the same random actions (E, T, A), and goals (E, G).

    The simulator side is `collect_transitions` on Gymnasium's env (episode k from seed + k), with
    the env settings the model's transitions were collected under (model.json's "env"), so the
    check sees exactly what `dynamics collect --simulator gymnasium` would record. Episodes that
    end early (an env's termination) keep their own length: the steps after an episode's end are
    NaN in "true" and "model", and "live" (E, T+1) says which steps exist.
    """
    fitted = model.meta.get("env")  # the env settings the model's transitions were collected under
    env = EnvConfig.model_validate(fitted) if isinstance(fitted, dict) else model.meta["env_id"]
    data = collect_transitions(env, episodes, workers=1, seed=seed, state=model.meta["state_layout"],
                               simulator="gymnasium", progress=False)
    rows = [np.flatnonzero(data.episode == e) for e in range(episodes)]
    horizon = int(min(max(len(r) for r in rows), steps or np.inf))
    lengths = np.array([min(len(r), horizon) for r in rows])
    padded = np.stack([np.pad(r[:horizon], (0, horizon - min(len(r), horizon)), mode="edge") for r in rows])
    live = np.arange(horizon + 1)[None, :] <= lengths[:, None]  # (E, T+1)
    true = np.concatenate([data.states[padded[:, :1]], data.next_states[padded]], axis=1)
    actions = data.actions[padded]
    s = torch.as_tensor(true[:, 0], dtype=torch.float32)
    predicted = [s]
    with torch.no_grad():
        for t in range(horizon):
            s = model.predict(s, torch.as_tensor(actions[:, t], dtype=torch.float32))
            predicted.append(s)
    model_states = torch.stack(predicted, 1).numpy().astype(np.float64)
    true[~live], model_states[~live] = np.nan, np.nan
    return {"true": true, "model": model_states, "actions": actions, "goals": data.goals[padded[:, 0]], "live": live}


def state_labels(env_id: str, labels: list[str], size: int) -> list[str]:
    """Names of the state's entries: the env's own observation labels where motorlab knows them
    (the observation layout), else the layout's."""
    from motorlab.envs.catalog import facts

    known = facts(env_id).obs_labels
    if known is not None and len(known) == size and all(x.startswith("obs[") for x in labels):
        return list(known)
    return labels if len(labels) == size else [f"state[{i}]" for i in range(size)]


def write_error_table(path, by_dim: np.ndarray, labels: list[str]) -> None:
    """error_by_dimension.csv: one row per step ahead, one column per state entry (normalized RMSE)."""
    from motorlab.runs import atomic_write_text

    rows = ["steps_ahead," + ",".join(f'"{x}"' for x in labels)]
    rows += [f"{h}," + ",".join(f"{v:.6g}" for v in row) for h, row in enumerate(by_dim)]
    atomic_write_text(path, "\n".join(rows) + "\n")


ROLLOUT_ERROR_STEPS = 50  # steps ahead measured at fit time (a planner's horizon beyond reuses the last)
ROLLOUT_ERROR_STARTS = 2000  # start rows sampled: the error of a mean needs no more
NORMAL_FROM_MEDIAN_ABS = 1.4826  # a normal's sigma over the median of its absolute values (1 / 0.6745)


def rollout_error(model: ForwardModel, data, rows: np.ndarray, steps: int = ROLLOUT_ERROR_STEPS,
                  seed: int = 0) -> np.ndarray | None:
    """The model's open-loop error on recorded episodes: (T, S), row t a robust standard deviation
    (1.4826 x the median absolute error, a normal's sigma) of each state entry's error after t + 1
    steps of feeding the model its own predictions under the recorded actions, from up to
    ROLLOUT_ERROR_STARTS start rows among `rows` (a transition set's row indices, e.g. its held-out
    episodes). A row's path stops at its episode's end. None when no start has a next step; a step
    ahead no path reaches repeats the last measured one.

    What the planner's termination probability reads (motorlab.planning.mpc.EndProbability): how
    far a predicted state may be from the true one t steps ahead.

    Why the median, not the root mean square: a few rows no model predicts (InvertedPendulum's cart
    hitting the end of its rail) ruled the mean of squares. On the loop's seed 2 (one held-out
    109-step episode, 10 rows at the rail) it gave 0.4 rad of pole angle 15 steps ahead, twice the
    0.2 rad the pole may lean, so every plan looked like a fall and the planner never balanced; the
    median's 0.003 rad is what that model's balancing seeds measured."""
    rows = np.asarray(rows)
    if len(rows) == 0:
        return None
    starts = np.random.default_rng(seed).choice(rows, size=min(len(rows), ROLLOUT_ERROR_STARTS), replace=False)
    # row r's successor within its episode is r + 1 (collection writes episodes row by row)
    episode = data.episode
    s = torch.as_tensor(data.states[starts], dtype=torch.float32)
    index = starts.copy()
    alive = np.ones(len(starts), bool)
    spread = np.zeros((steps, model.state_size))
    counts = np.zeros(steps)
    with torch.no_grad():
        for t in range(steps):
            s = model.predict(s, torch.as_tensor(data.actions[index], dtype=torch.float32))
            err = np.abs(s.numpy().astype(np.float64) - data.next_states[index])[alive]
            spread[t] = NORMAL_FROM_MEDIAN_ABS * np.median(err, 0)
            counts[t] = alive.sum()
            nxt = np.minimum(index + 1, len(episode) - 1)
            alive &= (~data.dones[index].astype(bool)) & (episode[nxt] == episode[index]) & (index + 1 < len(episode))
            if not alive.any():
                break
            index = np.where(alive, nxt, index)
    measured = counts > 0
    if not measured.any():
        return None
    out = spread[measured]
    out = np.concatenate([out, np.repeat(out[-1:], steps - len(out), 0)])
    return np.nan_to_num(out, nan=1e6, posinf=1e6)  # a diverging rollout: no trust at all, and valid JSON
