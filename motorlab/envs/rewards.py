"""Reward shaping: built-in options and user functions given as `module:function`.

A reward function has the signature
    fn(next_obs, action, reward, terminated, info) -> float
where `reward` is the task's own reward for that step.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

import numpy as np

from motorlab.envs.wrappers import RewardFn
from motorlab.errors import MotorlabError, did_you_mean


def task(obs, action, reward, terminated, info) -> float:
    """The task's own reward, unchanged."""
    return reward


def alive(obs, action, reward, terminated, info) -> float:
    """+1 for every step the episode goes on, 0 on the terminating step."""
    return 0.0 if terminated else 1.0


def quadratic(obs, action, reward, terminated, info) -> float:
    """Task reward minus 0.1 * |obs|^2: prefer staying near the origin
    (upright and centred for the pendulum)."""
    return reward - 0.1 * float(np.sum(np.square(obs)))


def action_penalty(obs, action, reward, terminated, info) -> float:
    """Task reward minus 0.01 * |action|^2: prefer gentle actuation."""
    return reward - 0.01 * float(np.sum(np.square(action)))


BUILTIN: dict[str, RewardFn] = {
    "task": task,
    "alive": alive,
    "quadratic": quadratic,
    "action-penalty": action_penalty,
}


def resolve_reward(spec: str) -> RewardFn:
    """A built-in name, `package.module:function`, or `path/to/file.py:function`.

    Raises:
        MotorlabError: unknown name, module that does not import, or missing function.
    """
    if spec in BUILTIN:
        return BUILTIN[spec]
    if ":" not in spec:
        raise MotorlabError(
            f"unknown reward {spec!r}{did_you_mean(spec, BUILTIN)}; use one of {', '.join(BUILTIN)} "
            "or a function as module:function."
        )
    module_name, _, func_name = spec.rpartition(":")
    try:
        if module_name.endswith(".py"):
            path = Path(module_name)
            if not path.is_file():
                raise MotorlabError(f"reward file {path} does not exist.")
            mod_spec = importlib.util.spec_from_file_location(path.stem, path)
            module = importlib.util.module_from_spec(mod_spec)
            mod_spec.loader.exec_module(module)
        else:
            if "" not in sys.path:
                sys.path.insert(0, "")  # allow modules in the working directory
            module = importlib.import_module(module_name)
    except MotorlabError:
        raise
    except Exception as e:
        raise MotorlabError(f"reward module {module_name!r} failed to import: {e}") from None
    fn = getattr(module, func_name, None)
    if not callable(fn):
        raise MotorlabError(f"reward {spec!r}: {module_name} has no function {func_name!r}.")
    return fn


def check_reward(spec: str) -> None:
    """The check of an env's --reward before any work (settings.UserCode): a built-in name, or the
    module (or .py file) and function it names, imported and found.

    Raises:
        MotorlabError: as `resolve_reward`.
    """
    resolve_reward(spec)
