"""Discrete-time PID on observations, batched over episodes.

    e_t = obs_t - setpoint
    u_t = Kp e_t + Ki sum_k e_k dt + Kd (e_t - e_{t-1}) / dt

Gains are per observation element (one row per action element), so a cart-pole
is balanced by gains on the pole angle and the cart position.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from motorlab.envs import env_dt, facts
from motorlab.envs.spaces import require_actions
from motorlab.errors import MotorlabError


def default_gains(env_id: str) -> dict[str, list[float]] | None:
    """The env's default gains (its catalogue entry's `pid_gains`: InvertedPendulum's, Upkie's, or
    what a user's env declares), or None."""
    gains = facts(env_id).pid_gains
    return None if gains is None else {k: list(g) for k, g in gains.items()}


@dataclass
class PIDController:
    """PID controller acting on a batch of observations.

    Args:
        kp, ki, kd: gains, shape (obs_dim,) for one action or (act_dim, obs_dim).
        dt: control period in seconds (the env's dt).
        low, high: action bounds; the output is clipped to them.
        setpoint: target observation (default zeros).
    """

    kp: np.ndarray
    ki: np.ndarray
    kd: np.ndarray
    dt: float
    low: np.ndarray
    high: np.ndarray
    setpoint: np.ndarray | None = None
    _integral: np.ndarray | None = field(default=None, repr=False)
    _prev: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self):
        self.kp, self.ki, self.kd = (np.atleast_2d(np.asarray(g, dtype=np.float64)) for g in (self.kp, self.ki, self.kd))
        if not (self.kp.shape == self.ki.shape == self.kd.shape):
            raise MotorlabError(f"PID gains must have one shape; got kp {self.kp.shape}, ki {self.ki.shape}, kd {self.kd.shape}.")
        if self.dt <= 0:
            raise MotorlabError(f"PID dt must be positive, got {self.dt}.")

    @property
    def obs_dim(self) -> int:
        return self.kp.shape[1]

    def reset(self, n: int) -> None:
        self._integral = np.zeros((n, self.obs_dim))
        self._prev = None

    def reset_row(self, i: int) -> None:
        """A new episode in row i alone: no integral, and no derivative kick on its first step."""
        self._integral[i] = 0.0
        if self._prev is not None:
            self._prev[i] = np.nan  # replaced by the row's first error on the next act()

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.atleast_2d(obs)
        if obs.shape[1] != self.obs_dim:
            raise MotorlabError(
                f"PID gains cover {self.obs_dim} observation elements but the env gives {obs.shape[1]}; "
                "give one gain per observation element."
            )
        if self._integral is None or self._integral.shape[0] != obs.shape[0]:
            self.reset(obs.shape[0])
        err = obs - (self.setpoint if self.setpoint is not None else 0.0)
        prev = err if self._prev is None else np.where(np.isnan(self._prev), err, self._prev)  # no kick at a start
        self._integral += err * self.dt
        u = err @ self.kp.T + self._integral @ self.ki.T + ((err - prev) / self.dt) @ self.kd.T
        self._prev = err.copy()
        return np.clip(u, self.low, self.high).astype(np.float32)

    def to_dict(self) -> dict:
        return {"type": "pid", "kp": self.kp.tolist(), "ki": self.ki.tolist(), "kd": self.kd.tolist(), "dt": self.dt,
                "low": np.asarray(self.low).tolist(), "high": np.asarray(self.high).tolist()}


def parse_gains(text: str) -> dict[str, list[float]]:
    """Parse 'kp=[1,20,0,0],kd=[1,3,0,0]' or 'kp=1;20;0;0,kd=...' into gain lists.

    A single number means that gain for every observation element.
    """
    gains: dict[str, list[float]] = {}
    if not text.strip():
        return gains
    for key, value in re.findall(r"(\w+)\s*=\s*(\[[^\]]*\]|[^,]+)", text):
        if key not in ("kp", "ki", "kd"):
            raise MotorlabError(f"unknown PID gain {key!r}; use kp, ki and kd, e.g. pid:kp=[1,20,0,0],kd=[1,3,0,0].")
        items = [v for v in re.split(r"[,;\s]+", value.strip("[] ")) if v]
        try:
            gains[key] = [float(v) for v in items]
        except ValueError:
            raise MotorlabError(f"PID gain {key}={value} is not a list of numbers, e.g. kp=[1,20,0,0].") from None
    leftover = re.sub(r"(\w+)\s*=\s*(\[[^\]]*\]|[^,]+)", "", text).replace(",", "").strip()
    if leftover:
        raise MotorlabError(f"cannot read PID gains {text!r}; write them as pid:kp=[1,20,0,0],ki=0,kd=[1,3,0,0].")
    return gains


def pid_for_env(spec: str, env, env_id: str) -> PIDController:
    """`make_pid` for a built env: its flat observation size, its dt and action bounds.

    Raises:
        MotorlabError: an env whose actions are not a Box (a PID's output is a continuous command),
            or bad gains.
    """
    require_actions(env.action_space, "the PID controller", env_id=env_id,
                    instead=f"evaluate a policy trained with `motorlab train {env_id} --algo ppo` instead")
    dt = env_dt(env)
    if dt is None:
        raise MotorlabError(f"the PID controller needs {env_id}'s step duration, and the env has no dt (nor a "
                            "MuJoCo timestep and frame skip); evaluate a trained policy instead.")
    return make_pid(spec, env_id, int(np.prod(env.observation_space.shape)), dt, env.action_space.low,
                    env.action_space.high)


def make_pid(spec: str, env_id: str, obs_dim: int, dt: float, low, high) -> PIDController:
    """PID from a spec 'pid' (default gains for the env) or 'pid:kp=...,ki=...,kd=...'."""
    _, _, text = spec.partition(":")
    defaults = default_gains(env_id)
    given = parse_gains(text)
    if defaults is None and not given:
        raise MotorlabError(f"no default PID gains for {env_id}; give them, e.g. pid:kp=[...],kd=[...] (or declare "
                            "them: motorlab.register_env(ENV_ID, pid_gains={'kp': [...], 'kd': [...]})).")
    base = defaults or {}
    full = {}
    for k in ("kp", "ki", "kd"):
        g = given.get(k, base.get(k, [0.0]))
        if len(g) == 1:
            g = g * obs_dim
        if len(g) != obs_dim:
            raise MotorlabError(f"PID gain {k} has {len(g)} values but {env_id} observations have {obs_dim}; give {obs_dim}.")
        full[k] = g
    return PIDController(full["kp"], full["ki"], full["kd"], dt=dt, low=np.asarray(low), high=np.asarray(high))
