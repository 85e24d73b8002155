"""Gymnasium wrappers for robust-policy studies: delay and reward shaping.

Observation history uses Gymnasium's own FrameStackObservation + FlattenObservation
(see `motorlab.envs.make_env`); only what Gymnasium lacks is written here.
"""

from __future__ import annotations

import sys
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from motorlab.envs.disturbances import EpisodeRandom, env_dt_of, parse_span, record_draws
from motorlab.errors import MotorlabError
from motorlab.faults import FAULT_KEY

DelayOn = Literal["action", "observation", "both"]

# fn(next_obs, action, reward, terminated, info) -> shaped reward
RewardFn = Callable[[np.ndarray, np.ndarray, float, bool, dict], float]


def delay_alpha(dt: float, time_constant: float) -> float:
    """Filter coefficient of a first-order low-pass: alpha = dt / time_constant.

    Raises:
        MotorlabError: unless 0 < alpha < 1 (time constant longer than one step).
    """
    if not np.isfinite(time_constant) or time_constant <= 0:
        raise MotorlabError(f"delay time constant must be a positive number of seconds, got {time_constant}.")
    alpha = dt / time_constant
    if not 0.0 < alpha < 1.0:
        raise MotorlabError(
            f"delay time constant {time_constant} s gives alpha = dt/tau = {dt}/{time_constant} = {alpha:.3g}; "
            f"alpha must be in (0, 1), so choose a time constant above the env's step dt = {dt} s."
        )
    return alpha


class LowPassDelay(EpisodeRandom, gym.utils.RecordConstructorArgs):
    """Actuation and/or perception delay as a first-order low-pass filter.

    Each step `y <- y + alpha * (x - y)` with `alpha = dt / time_constant`, where x
    is the commanded action (actuation delay) or the true observation (perception
    delay). The filter restarts with every episode: the action filter at zero
    (clipped into the action space), the observation filter at the first observation.

    Args:
        env: an env with a Box action space and a `dt` (MuJoCo envs have one).
        time_constant: seconds; must exceed the env's dt. A range "LOW..HIGH" draws the
            time constant anew each episode (domain randomization); a draw at or below dt
            means no lag in that episode (alpha = 1).
        on: "action", "observation" or "both".
    """

    SALT = 5

    def __init__(self, env: gym.Env, time_constant: float | str, on: DelayOn = "both"):
        gym.utils.RecordConstructorArgs.__init__(self, time_constant=time_constant, on=on)
        super().__init__(env)
        if on not in ("action", "observation", "both"):
            raise MotorlabError(f"delay must act on 'action', 'observation' or 'both', got {on!r}.")
        dt = env_dt_of(env.unwrapped)
        if dt is None:
            raise MotorlabError(f"{env.spec.id if env.spec else env} has no step dt; delay needs one.")
        if on in ("action", "both") and not isinstance(env.action_space, gym.spaces.Box):
            raise MotorlabError("a delay on actions needs a continuous (Box) action space; give --delay-on observation.")
        self.dt = float(dt)
        self.span = parse_span(time_constant, "delay time constant (s)")
        if self.span[0] == self.span[1]:
            delay_alpha(self.dt, self.span[0])  # a fixed time constant must lag: dt < tau
        self.time_constant = self.span[1]
        self.alpha = self._alpha(self.time_constant)
        self.on = on
        space = env.action_space
        self._action_rest = (np.clip(np.zeros(space.shape), space.low, space.high).astype(space.dtype)
                             if self.filters_action else np.zeros(0))  # the lag's rest command (Box actions only)
        self._action = self._action_rest.copy()
        self._obs: np.ndarray | None = None

    def _alpha(self, tau: float) -> float:
        return 1.0 if tau <= self.dt else self.dt / tau

    @property
    def filters_action(self) -> bool:
        return self.on in ("action", "both")

    @property
    def filters_observation(self) -> bool:
        return self.on in ("observation", "both")

    def reset(self, **kwargs: Any):
        self._seed(kwargs)
        obs, info = self.env.reset(**kwargs)
        if self.span[0] != self.span[1]:
            self.time_constant = self.draw(self.span)
            self.alpha = self._alpha(self.time_constant)
            record_draws(info, delay=self.time_constant)
        self._action = self._action_rest.copy()
        self._obs = np.array(obs, copy=True)
        return self._obs.copy(), info

    def step(self, action):
        if self.filters_action:
            action = np.asarray(action, dtype=self._action.dtype)
            self._action = (self._action + self.alpha * (action - self._action)).astype(self._action.dtype)
            action = self._action
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.filters_observation:
            self._obs = (self._obs + self.alpha * (obs - self._obs)).astype(obs.dtype)
            obs = self._obs.copy()
        info["applied_action"] = np.array(action, copy=True)
        return obs, reward, terminated, truncated, info


class RewardShaping(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Replace the reward with `fn(next_obs, action, reward, terminated, info)`.

    The task's own reward is kept in `info["task_reward"]`, so evaluation can
    still report the return the task defines.
    """

    def __init__(self, env: gym.Env, fn: RewardFn, name: str = "custom"):
        gym.utils.RecordConstructorArgs.__init__(self, fn=fn, name=name)
        super().__init__(env)
        self.fn = fn
        self.name = name

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["task_reward"] = float(reward)
        try:
            shaped = float(self.fn(obs, np.asarray(action), float(reward), bool(terminated), info))
        except MotorlabError:
            raise
        except Exception as e:  # the user's function may raise anything: one line naming it
            raise user_code_error(f"--reward {self.name}", e) from None
        return obs, shaped, terminated, truncated, info


class NumericalGuard(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """End an episode whose simulation went numerically bad, instead of crashing the run.

    A step whose observation or reward is NaN/Inf, or after which MuJoCo reports a
    new instability warning (bad accelerations; MyoSuite's hand can blow up), is
    made terminal: the observation is zeroed where not finite, the reward is 0,
    and `info["numerical_fault"]` names the cause so the run can count it.
    """

    def __init__(self, env: gym.Env, env_id: str | None = None):
        gym.utils.RecordConstructorArgs.__init__(self, env_id=env_id)
        super().__init__(env)
        self.env_id = env_id or (env.spec.id if env.spec else type(env.unwrapped).__name__)
        self._data = getattr(env.unwrapped, "mj_data", None) or getattr(env.unwrapped, "data", None)
        self._warnings = self._warning_count()

    def _warning_count(self) -> int:
        # MuJoCo reports divergence as BADQPOS/BADQVEL/BADQACC warnings (and resets the state itself).
        try:
            import mujoco

            w = mujoco.mjtWarning
            return sum(int(self._data.warning[k].number) for k in (w.mjWARN_BADQPOS, w.mjWARN_BADQVEL, w.mjWARN_BADQACC))
        except (AttributeError, TypeError, IndexError, ImportError):
            return 0

    def reset(self, **kwargs: Any):
        obs, info = self._call("reset", self.env.reset, **kwargs)
        self._warnings = self._warning_count()
        return obs, info

    def _call(self, what: str, method: Callable, *args: Any, **kwargs: Any) -> Any:
        """The env's own method; whatever it raises (other than motorlab's own errors) becomes one
        line naming the env, the exception and where it was raised (`user_code_error`)."""
        try:
            return method(*args, **kwargs)
        except MotorlabError:
            raise
        except Exception as e:  # the env's code (often a user's) may raise anything
            raise user_code_error(f"{self.env_id}'s {what}", e) from None

    def step(self, action):
        obs, reward, terminated, truncated, info = self._call("step", self.env.step, action)
        fault = None
        arrays = obs.values() if isinstance(obs, dict) else (obs,)  # a Dict observation: every key
        if not all(np.all(np.isfinite(a)) for a in arrays):
            fault = "non-finite observation"
        elif not np.isfinite(reward):
            fault = "non-finite reward"
        else:
            count = self._warning_count()
            if count > self._warnings:
                fault = "simulation instability (MuJoCo reset a diverging state)"
            self._warnings = count
        if fault is None:
            return obs, reward, terminated, truncated, info
        info[FAULT_KEY] = fault
        obs = ({k: _finite(v) for k, v in obs.items()} if isinstance(obs, dict) else _finite(obs))
        return obs, 0.0, True, truncated, info


def _finite(a: Any) -> np.ndarray:
    """`a` with its non-finite entries zeroed, in its own dtype."""
    return np.where(np.isfinite(a), a, 0.0).astype(np.asarray(a).dtype)


class EpisodeCap(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """An env with no time limit (registered without max_episode_steps): an episode that runs
    `cap` steps without ending stops the run with one line saying how to give it a limit, instead
    of evaluation waiting forever. Envs that end their episodes themselves never meet it."""

    def __init__(self, env: gym.Env, env_id: str, cap: int):
        gym.utils.RecordConstructorArgs.__init__(self, env_id=env_id, cap=cap)
        super().__init__(env)
        self.env_id, self.cap, self.t = env_id, cap, 0

    def reset(self, **kwargs: Any):
        self.t = 0
        return self.env.reset(**kwargs)

    def step(self, action):
        out = self.env.step(action)
        self.t = 0 if (out[2] or out[3]) else self.t + 1
        if self.t >= self.cap:
            raise MotorlabError(f"{self.env_id} has no time limit and an episode ran {self.cap:,} steps without "
                                "ending; give it one: --env-arg max_episode_steps=N (a recipe's env_kwargs), or "
                                "register it with max_episode_steps=N.")
        return out


def has_time_limit(env: gym.Env) -> bool:
    """Whether a TimeLimit wrapper ends `env`'s episodes (Gymnasium adds one for an id registered
    with max_episode_steps, or made with max_episode_steps=N), anywhere in its wrapper chain."""
    layer: Any = env
    while layer is not None:
        if isinstance(layer, gym.wrappers.TimeLimit):
            return True
        layer = getattr(layer, "env", None)
    return False


# ---- the user's code failing ------------------------------------------------------------------

_LIBRARIES = tuple(str(Path(p).resolve()) for p in {sys.prefix, sys.base_prefix, sys.exec_prefix})
_OURS = str(Path(__file__).resolve().parents[1])


def where_raised(e: BaseException) -> str:
    """Where `e` was raised, as "file.py:12 in step": the innermost frame of code that is neither
    motorlab's nor an installed library's (the user's), else the innermost frame."""
    frames = traceback.extract_tb(e.__traceback__)
    if not frames:
        return "unknown place"

    def theirs(frame: traceback.FrameSummary) -> bool:
        path = str(Path(frame.filename).resolve())
        return not path.startswith(_LIBRARIES) and not path.startswith(_OURS)

    frame = next((f for f in reversed(frames) if theirs(f)), frames[-1])
    return f"{frame.filename}:{frame.lineno} in {frame.name}"


class UserCodeError(MotorlabError):
    """A user's env or function raised: one line naming it (an env worker adds which worker)."""


def user_code_error(what: str, e: BaseException) -> UserCodeError:
    """One line for an exception raised by a user's env or function (`what`: "MyArm-v0's step",
    "--reward mypkg:shaped"): its type, its message's first line, and where it was raised."""
    message = " ".join(str(e).split()) or "(no message)"
    return UserCodeError(f"{what} raised {type(e).__name__}: {message} (at {where_raised(e)}); fix it there, "
                         "then run the command again.")
