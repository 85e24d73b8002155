"""`transitions.npz`: what `motorlab dynamics collect` writes and `dynamics fit` reads.

Plain arrays (no pickle), one row per env step:
    states (N, S), actions (N, A), next_states (N, S), rewards (N,), dones (N,)
    (episode ended: terminated or truncated), terminated (N,), episode (N,) (index of
    the episode the row belongs to), goals (N, G) (the planner's goal, e.g. Reacher's
    target; G = 0 for goal-free layouts)
and `meta`, a JSON string: env id, state layout and labels, policy, seed, collector, the action
space (`action_space`, as motorlab.envs.spaces.encode_space writes it) and, for an env with a Dict
observation, where each of its keys lies in the flat observation (`obs_layout`: a list of
{key, start, stop, shape}, e.g. observation, achieved_goal, desired_goal; null otherwise).

Reading one never unpickles: a file that is not a plain .npz archive is refused in one line
(`read_npz`), whatever numpy would suggest.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.runs import NpzUnreadable, atomic_write_npz, first_line, read_npz

TRANSITIONS = "transitions.npz"
_ARRAYS = ("states", "actions", "next_states", "rewards", "dones", "terminated", "episode", "goals")
_TABLES = ("states", "actions", "next_states", "goals")  # 2-D; the others hold one entry per row


@dataclass
class Transitions:
    states: np.ndarray
    actions: np.ndarray
    next_states: np.ndarray
    rewards: np.ndarray
    dones: np.ndarray
    terminated: np.ndarray
    episode: np.ndarray
    goals: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.states)

    @property
    def env_id(self) -> str:
        return self.meta.get("env_id", "?")

    def save(self, path: Path) -> None:
        atomic_write_npz(path, **{k: getattr(self, k) for k in _ARRAYS}, meta=np.array(json.dumps(self.meta)))

    def check(self, source: str = "transitions") -> Transitions:
        """Shapes agree and every number is finite, or one clear MotorlabError."""
        fix = "re-run `motorlab dynamics collect`."
        for name in _ARRAYS:
            arr = np.asarray(getattr(self, name))
            ndim = 2 if name in _TABLES else 1
            kinds = {"dones": "biu", "terminated": "biu", "episode": "iu"}.get(name, "fiu")
            if arr.ndim != ndim or arr.dtype.kind not in kinds:
                what = "2-D (rows x entries)" if ndim == 2 else "1-D (one per row)"
                raise MotorlabError(f"{source}: {name} must be a {what} array of "
                                    f"{ {'biu': 'flags', 'iu': 'integers'}.get(kinds, 'numbers')}, got shape {arr.shape} "
                                    f"of {arr.dtype}; {fix}")
        n = len(self.states)
        if n == 0:
            raise MotorlabError(f"{source} holds no transitions; collect at least one episode.")
        if self.next_states.shape != self.states.shape:
            raise MotorlabError(f"{source}: next_states {self.next_states.shape} and states {self.states.shape} "
                                f"differ in shape; {fix}")
        for name in ("actions", "rewards", "dones", "terminated", "episode", "goals"):
            if len(getattr(self, name)) != n:
                raise MotorlabError(f"{source}: {name} has {len(getattr(self, name))} rows, states {n}; {fix}")
        for name in ("states", "actions", "next_states", "rewards", "goals"):
            bad = ~np.isfinite(getattr(self, name))
            if bad.any():
                row = int(np.argwhere(bad)[0][0])
                raise MotorlabError(f"{source}: {name} holds NaN or Inf ({int(bad.sum())} entries, first in row {row}); "
                                    f"drop those episodes or {fix}")
        check_meta(self.meta, self.states.shape[1], source, fix)
        return self


def concatenate(parts: list[Transitions], meta: dict[str, Any] | None = None) -> Transitions:
    """The rows of several transition sets as one (episode indices as they are: keep them distinct),
    with the first part's meta unless `meta` is given."""
    arrays = {k: np.concatenate([getattr(p, k) for p in parts]) for k in _ARRAYS}
    return Transitions(**arrays, meta=dict(parts[0].meta if meta is None else meta))


def check_meta(meta: dict, state_size: int, source: str, fix: str) -> None:
    """The descriptive fields that transitions.npz and model.json share have the right types:
    env id and layout name strings, one label per state entry."""
    def bad(field: str, want: str) -> MotorlabError:
        return MotorlabError(f"{source}: {field} should be {want}, got {meta.get(field)!r}; {fix}")

    if not isinstance(meta.get("env_id"), str) or not meta["env_id"]:
        raise bad("env_id", "an env id such as 'Reacher-v5'")
    if not isinstance(meta.get("state_layout"), str):
        raise bad("state_layout", "a layout name (reacher, observation)")
    for key, size in (("state_labels", state_size), ("goal_labels", None)):
        labels = meta.get(key)
        if labels is not None and (not isinstance(labels, list) or not all(isinstance(x, str) for x in labels)
                                   or (size is not None and len(labels) != size)):
            raise bad(key, f"a list of {size} names" if size is not None else "a list of names")
    obs_dim = meta.get("obs_dim")
    if obs_dim is not None and (not isinstance(obs_dim, int) or isinstance(obs_dim, bool) or obs_dim < 1):
        raise bad("obs_dim", "a positive integer")
    if not _is_obs_layout(meta.get("obs_layout"), obs_dim):
        raise bad("obs_layout", "null or a list of {key, start, stop, shape}, one after another, covering "
                  "the observation")
    space = meta.get("action_space")
    if space is not None and not (isinstance(space, dict) and isinstance(space.get("type"), str)):
        raise bad("action_space", "an action space as motorlab writes it ({\"type\": \"Box\", ...})")


def _is_count(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _is_obs_layout(value, obs_dim: int | None) -> bool:
    """None, or key slices that tile the flat observation from 0 (to obs_dim, where it is known)."""
    if value is None:
        return True
    if not isinstance(value, list) or not value:
        return False
    stop = 0
    for item in value:
        if not (isinstance(item, dict) and isinstance(item.get("key"), str) and _is_count(item.get("start"))
                and _is_count(item.get("stop")) and item["start"] == stop and item["stop"] > stop
                and isinstance(item.get("shape"), list) and all(_is_count(d) for d in item["shape"])):
            return False
        stop = item["stop"]
    return obs_dim is None or stop == obs_dim


def load_transitions(path: Path) -> Transitions:
    """Read and check a transitions.npz (or the run folder holding one), without unpickling."""
    path = Path(path)
    if path.is_dir():
        path = path / TRANSITIONS
    if not path.is_file():
        raise MotorlabError(f"{path} is missing; write it with `motorlab dynamics collect ENV_ID --out DIR`.")

    def not_transitions(reason: str) -> MotorlabError:
        return MotorlabError(f"{path} is not a transitions file written by `motorlab dynamics collect` ({reason}); "
                             "re-run `motorlab dynamics collect`.")

    try:
        found = read_npz(path)
    except NpzUnreadable as e:
        raise not_transitions(str(e)) from None
    missing = [k for k in (*_ARRAYS, "meta") if k not in found]
    if missing:
        raise not_transitions(f"it lacks {', '.join(missing)}")
    try:
        meta = json.loads(str(found["meta"]))
    except ValueError as e:
        raise not_transitions(f"its meta is not JSON: {first_line(e)}") from None
    if not isinstance(meta, dict):
        raise not_transitions("its meta is not a JSON object")
    return Transitions(**{k: found[k] for k in _ARRAYS}, meta=meta).check(str(path))
