"""Observation and action spaces beyond one Box: Dict observations (goal-conditioned tasks) and
discrete actions, in one convention every part of motorlab shares.

- **Dict observations** are flattened the way Gymnasium flattens them
  (`gymnasium.spaces.flatten`: keys in the Dict's order, each key's array raveled). Everything
  that only needs numbers (evaluation, robustness, dynamics, MPC, synergies, ONNX) sees that flat
  vector; `obs_layout` says which slice holds which key, and run folders record it. Only SB3
  training keeps the Dict (MultiInputPolicy; hindsight relabelling needs the goal keys), and a
  policy trained on a Dict turns a flat batch back into one (`unflatten_batch`) before it acts.
- **Spaces in JSON** (`encode_space` / `decode_space`): Box bounds as strings (so +-inf survive),
  Discrete, MultiDiscrete, MultiBinary and Dict of those; a policy.json or model.json names its spaces.
- **Who can use which space** (`require_actions`): one line naming the space and what fits it,
  before any work starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from motorlab.errors import MotorlabError

GOAL_KEYS = ("observation", "achieved_goal", "desired_goal")


@dataclass(frozen=True)
class KeySlice:
    """Where one key of a Dict observation lies in the flat vector: [start, stop), with its shape."""

    key: str
    start: int
    stop: int
    shape: tuple[int, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "start": self.start, "stop": self.stop, "shape": list(self.shape)}


def is_dict(space: gym.Space) -> bool:
    return isinstance(space, gym.spaces.Dict)


def obs_layout(space: gym.Space) -> list[KeySlice]:
    """The slices of a Dict observation's keys in its flat vector (empty for any other space).

    Raises:
        MotorlabError: a key that is not a Box (nested Dicts, images of other types, text).
    """
    if not is_dict(space):
        return []
    slices, start = [], 0
    for key, sub in space.spaces.items():
        if not isinstance(sub, gym.spaces.Box):
            raise MotorlabError(f"observation key {key!r} is a {type(sub).__name__}; motorlab handles Dict "
                                "observations of Box entries (flatten the others in a wrapper of your env).")
        size = int(np.prod(sub.shape))
        slices.append(KeySlice(str(key), start, start + size, tuple(int(d) for d in sub.shape)))
        start += size
    return slices


def layout_json(space: gym.Space) -> list[dict[str, Any]] | None:
    """`obs_layout` as JSON for run folders (None for a plain Box)."""
    return [s.to_dict() for s in obs_layout(space)] or None


def unflatten_batch(obs: np.ndarray, layout: list[KeySlice]) -> dict[str, np.ndarray]:
    """A batch of flat observations (n, size) as the Dict the network was trained on."""
    return {s.key: obs[:, s.start:s.stop].reshape(len(obs), *s.shape) for s in layout}


def flatten_batch(obs: dict[str, np.ndarray], layout: list[KeySlice]) -> np.ndarray:
    """A batch of Dict observations as flat vectors (n, size), in `layout`'s order."""
    n = len(next(iter(obs.values())))
    return np.concatenate([np.asarray(obs[s.key]).reshape(n, -1) for s in layout], axis=1)


def is_goal_conditioned(env: gym.Env) -> bool:
    """A goal-conditioned task in Gymnasium-Robotics' sense, which hindsight relabelling (HER) needs:
    a Dict observation with achieved_goal and desired_goal, and `compute_reward` on the env."""
    space = env.observation_space
    return (is_dict(space) and {"achieved_goal", "desired_goal"} <= set(space.spaces)
            and callable(getattr(env.unwrapped, "compute_reward", None)))


def describe_space(space: gym.Space) -> str:
    """A space in a few words for messages: "Discrete(3)", "Box(6,)", "Dict(achieved_goal, ...)"."""
    if isinstance(space, gym.spaces.Box):
        return f"Box{tuple(space.shape)}"
    if isinstance(space, gym.spaces.Discrete):
        return f"Discrete({int(space.n)})"
    if is_dict(space):
        return f"Dict({', '.join(map(str, space.spaces))})"
    return str(space)


def require_actions(space: gym.Space, user: str, fits: str = "continuous (Box) actions",
                    instead: str = "", env_id: str | None = None) -> None:
    """Refuse, in one line, a component that needs Box actions on an env whose actions are not.

    Args:
        user: what refuses, e.g. "SAC", "MPC", "the PID controller".
        fits: what it needs.
        instead: what does fit this env, e.g. "use --algo ppo".
        env_id: the env, named in the message ("CartPole-v1's actions are Discrete(2)").

    Raises:
        MotorlabError: e.g. "SAC needs continuous (Box) actions, and CartPole-v1's actions are
            Discrete(2); use --algo ppo."
    """
    if isinstance(space, gym.spaces.Box):
        return
    whose = f"{env_id}'s" if env_id else "this env's"
    raise MotorlabError(f"{user} needs {fits}, and {whose} actions are {describe_space(space)}"
                        + (f"; {instead}" if instead else "") + ".")


def flat_space(space: gym.Space) -> gym.Space:
    """The space of the observations motorlab's evaluation envs give: a Dict flattened as
    `gymnasium.spaces.flatten_space` does (a Box in `obs_layout` order); any other space as it is."""
    return gym.spaces.flatten_space(space) if is_dict(space) else space


def env_actions(actions: np.ndarray, space: gym.Space) -> np.ndarray:
    """A batch of policy actions in the dtype the env's action space takes: float32 for a Box,
    int64 for Discrete (an env rejects an action index given as a float)."""
    if isinstance(space, (gym.spaces.Discrete, gym.spaces.MultiDiscrete, gym.spaces.MultiBinary)):
        return np.asarray(actions).astype(np.int64)
    return np.asarray(actions, dtype=np.float32)


# ---- spaces as JSON ------------------------------------------------------------------------

def encode_space(space: gym.Space) -> dict[str, Any]:
    """A space as JSON (no pickle): its type and what rebuilds it."""
    if isinstance(space, gym.spaces.Box):
        # bounds as strings so that +-inf survive JSON ("inf" is not JSON)
        return {"type": "Box", "shape": list(space.shape), "dtype": str(space.dtype),
                "low": [repr(float(v)) for v in space.low.ravel()],
                "high": [repr(float(v)) for v in space.high.ravel()]}
    if isinstance(space, gym.spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, gym.spaces.MultiDiscrete):
        return {"type": "MultiDiscrete", "nvec": space.nvec.tolist()}
    if isinstance(space, gym.spaces.MultiBinary):
        return {"type": "MultiBinary", "n": np.asarray(space.n).tolist()}
    if is_dict(space):
        return {"type": "Dict", "spaces": {str(k): encode_space(v) for k, v in space.spaces.items()}}
    raise MotorlabError(f"{type(space).__name__} spaces cannot be saved by motorlab; "
                        "use Box, Discrete, MultiDiscrete, MultiBinary or a Dict of them.")


def decode_space(d: dict[str, Any]) -> gym.Space:
    """The space `encode_space` wrote (policy.json files older than Dict support hold a bare Box)."""
    kind = d.get("type", "Box")
    if kind == "Box":
        shape, dtype = tuple(d["shape"]), np.dtype(d["dtype"])
        low = np.array([float(v) for v in d["low"]], dtype=dtype).reshape(shape)
        high = np.array([float(v) for v in d["high"]], dtype=dtype).reshape(shape)
        return gym.spaces.Box(low=low, high=high, dtype=dtype)
    if kind == "Discrete":
        return gym.spaces.Discrete(int(d["n"]), start=int(d.get("start", 0)))
    if kind == "MultiDiscrete":
        return gym.spaces.MultiDiscrete(d["nvec"])
    if kind == "MultiBinary":
        return gym.spaces.MultiBinary(d["n"])
    if kind == "Dict":
        return gym.spaces.Dict({k: decode_space(v) for k, v in d["spaces"].items()})
    raise ValueError(f"unknown space type {kind!r}")


# ---- what motorlab can read and act in: checked when an env is made -----------------------------

# action spaces some motorlab policy acts in (each component then declares its own: algos)
ACTION_SPACES = ("Box", "Discrete", "MultiDiscrete", "MultiBinary")
READABLE = "a Box of numbers (not an image), or a Dict of such Boxes"
FLATTEN_HINT = "wrap your env in gymnasium.wrappers.FlattenObservation (or give it vector observations)"


def is_image(space: gym.Space) -> bool:
    """A Box of pixels as SB3 reads one: uint8 with 2 or 3 dimensions. motorlab trains MLPs, which
    would learn from raw pixels as numbers, and SB3 turns such a space into a channel-first image
    on its own, which evaluation then no longer matches."""
    return isinstance(space, gym.spaces.Box) and space.dtype == np.uint8 and len(space.shape) >= 2


def observation_problem(space: gym.Space) -> str | None:
    """Why no motorlab policy reads observations of `space` (None: they are fine).

    motorlab's policies read one vector of numbers (a Dict's keys flattened into it): a Box that
    is not an image, or a Dict of those.
    """
    if is_dict(space):
        for key, sub in space.spaces.items():
            if is_image(sub) or not isinstance(sub, gym.spaces.Box) or observation_problem(sub):
                what = "an image" if is_image(sub) else f"a {type(sub).__name__}"
                return f"a Dict whose key {key!r} is {what} ({describe_space(sub)})"
        return None
    if is_image(space):
        return f"an image ({describe_space(space)} uint8)"
    if not isinstance(space, gym.spaces.Box):
        return f"{describe_space(space)}"
    if space.shape == () or int(np.prod(space.shape)) == 0:
        return f"{describe_space(space)}, which holds no vector"
    return None


def check_spaces(env: gym.Env, env_id: str) -> None:
    """Refuse, in one line naming the space and what would work, an env whose observations no
    motorlab policy reads or whose actions none acts in. `make_env` calls it on every env it makes,
    so every kind refuses such an env at its door, before any work or file; what one component
    needs beyond this (Box actions, bounded ones) it declares itself (`require_actions`,
    motorlab.algos' `actions`).

    Raises:
        MotorlabError: e.g. "MyEnv-v0's observations are Tuple(...); motorlab reads a Box of numbers
            (not an image), or a Dict of such Boxes: wrap your env in ...FlattenObservation ...".
    """
    problem = observation_problem(env.observation_space)
    if problem:
        raise MotorlabError(f"{env_id}'s observations are {problem}; motorlab's policies read {READABLE}: "
                            f"{FLATTEN_HINT}.")
    act = env.action_space
    if type(act).__name__ not in ACTION_SPACES or (isinstance(act, gym.spaces.Box) and act.shape == ()):
        raise MotorlabError(f"{env_id}'s actions are {describe_space(act)}; motorlab's policies act in "
                            f"{', '.join(ACTION_SPACES[:-1])} or {ACTION_SPACES[-1]} actions: give your env one "
                            "of those (gymnasium.spaces.flatten_space makes a Box of a Tuple or Dict).")
