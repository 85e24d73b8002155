"""Upkie wheeled biped envs (the `upkie` package, PyBullet backend), set up for learning.

`upkie.envs.register()` adds ids `Upkie-<Backend>-<ActionSpace>`, e.g.
`Upkie-PyBullet-Pendulum` (observation: pitch, ground position, pitch rate, ground
velocity; action: commanded ground velocity). Upkie's own defaults suit a robot:
a GUI window, a loop throttled to real time, no time limit and reward 0. motorlab's
defaults suit learning: headless, unthrottled, 200 Hz, 10 s episodes (2,000 steps),
and a balancing reward (`balance_reward`). Any of them can be changed through the
env's keyword arguments (`EnvConfig.kwargs`, `--env-arg KEY=VALUE`):

    frequency = 200.0            # control loop, Hz (PyBullet runs 1 kHz substeps)
    time_limit = 10.0            # seconds per episode (or max_episode_steps directly)
    gui = false, regulate_frequency = false
    fall_pitch = 1.0, max_ground_velocity = 3.0     # Upkie's own pendulum settings
    init_rand = { pitch = 0.1, omega_y = 0.5 }      # initial-state randomization (Upkie's update_init_rand)

PyBullet keeps a default client per process, so one process holds one Upkie env;
`make_upkie` builds the first in this process and any further ones in child
processes (`ProcessEnv`).
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import logging
import os
import sys
from typing import Any

import gymnasium as gym
import numpy as np

from motorlab.envs.isolated import ProcessEnv
from motorlab.errors import MotorlabError
from motorlab.extras import require

DEFAULTS: dict[str, Any] = {"gui": False, "regulate_frequency": False, "frequency": 200.0, "time_limit": 10.0}

# Balancing reward: 1 for every step the robot stays up, plus up to 0.5 for being
# upright and up to 0.5 for standing still; 0 on the step it falls.
PITCH_SCALE = 0.1  # rad: the upright term is exp(-(pitch / 0.1)^2)
VELOCITY_SCALE = 0.5  # m/s: the stillness term is exp(-(ground velocity / 0.5)^2)


def register_upkie() -> None:
    """Register the Upkie ids with Gymnasium.

    Raises:
        MotorlabError: upkie or pybullet not installed (the `upkie` extra).
    """
    if "Upkie-PyBullet-Pendulum" in gym.registry:
        return
    upkie_envs = require("upkie.envs", "upkie", "Upkie envs need the upkie package")
    with _quiet_c_output():  # PyBullet prints its build time to stderr on import
        # upkie imports pybullet lazily; fail here, clearly
        require("pybullet", "upkie", "Upkie's PyBullet backend needs pybullet")
    # Upkie logs a warning at every fall; in training that is thousands of lines. Falls
    # are counted in info["fell"] and the evaluation summary instead.
    logging.getLogger("upkie").setLevel(logging.ERROR)
    upkie_envs.register()


@contextlib.contextmanager
def _quiet_c_output():
    """Silence file descriptors 1 and 2 (C-level prints) for the duration."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
        yield
        ctypes.CDLL(None).fflush(None)  # C stdio buffers output to a pipe: flush it while it goes nowhere
    finally:
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


def balance_reward(pitch: float, ground_velocity: float, fell: bool) -> float:
    """motorlab's default Upkie reward (Upkie itself returns 0): alive, upright and still."""
    if fell:
        return 0.0
    return 1.0 + 0.5 * float(np.exp(-(pitch / PITCH_SCALE) ** 2)) + 0.5 * float(np.exp(-(ground_velocity / VELOCITY_SCALE) ** 2))


class BalanceReward(gym.Wrapper):
    """Puts `balance_reward` in place of Upkie's reward of 0 and marks outcomes in `info`:
    `fell` (Upkie's fall detection ended the episode) and `success` (the time limit was
    reached standing). Reads the robot state from Upkie's spine observation, so it works
    for every Upkie action space."""

    def step(self, action):
        obs, _, terminated, truncated, info = self.env.step(action)
        spine = info["spine_observation"]
        pitch = float(spine["base_orientation"]["pitch"])
        velocity = float(spine["wheel_odometry"]["velocity"])
        info["fell"] = bool(terminated)
        info["success"] = bool(truncated and not terminated)
        return obs, balance_reward(pitch, velocity, terminated), terminated, truncated, info


class PyBulletCamera(gym.Wrapper):
    """`render()` for the PyBullet backend: an RGB frame from PyBullet's CPU renderer
    (no display or GPU needed), a camera beside the robot that follows it."""

    def __init__(self, env: gym.Env, width: int = 640, height: int = 480):
        super().__init__(env)
        self.width, self.height = width, height

    @property
    def render_mode(self) -> str:
        return "rgb_array"

    def render(self) -> np.ndarray:
        import pybullet

        robot = max(pybullet.getBodyUniqueId(i) for i in range(pybullet.getNumBodies()))  # the plane loads first
        (x, y, _), _ = pybullet.getBasePositionAndOrientation(robot)
        view = pybullet.computeViewMatrixFromYawPitchRoll([x, y, 0.35], distance=1.6, yaw=60.0, pitch=-15.0,
                                                          roll=0.0, upAxisIndex=2)
        projection = pybullet.computeProjectionMatrixFOV(fov=50.0, aspect=self.width / self.height,
                                                          nearVal=0.05, farVal=20.0)
        _, _, rgba, _, _ = pybullet.getCameraImage(self.width, self.height, view, projection,
                                                   renderer=pybullet.ER_TINY_RENDERER)
        return np.asarray(rgba, dtype=np.uint8).reshape(self.height, self.width, 4)[..., :3].copy()


def settings(kwargs: dict[str, Any]) -> dict[str, Any]:
    """motorlab's defaults under the user's keyword arguments; `time_limit` (seconds)
    becomes Gymnasium's max_episode_steps unless that is given."""
    merged = {**DEFAULTS, **kwargs}
    time_limit = merged.pop("time_limit")
    frequency = merged["frequency"]
    if not isinstance(frequency, (int, float)) or frequency <= 0:
        raise MotorlabError(f"Upkie frequency must be a positive number of Hz, got {frequency!r}.")
    if "max_episode_steps" not in merged:
        if not isinstance(time_limit, (int, float)) or time_limit <= 0:
            raise MotorlabError(f"Upkie time_limit must be a positive number of seconds, got {time_limit!r}.")
        merged["max_episode_steps"] = max(1, round(time_limit * frequency))
    return merged


def build(env_id: str, render_mode: str | None, kwargs: dict[str, Any]) -> gym.Env:
    """The Upkie env with motorlab's defaults, reward and (for rgb_array) camera, in this process."""
    register_upkie()
    merged = settings(kwargs)
    init_rand = merged.pop("init_rand", None)
    try:
        env = gym.make(env_id, **merged)
    except TypeError as e:  # an unknown keyword argument
        raise MotorlabError(f"{env_id} does not take these settings ({e}); "
                            f"motorlab's are {', '.join(DEFAULTS)}, max_episode_steps and init_rand.") from None
    except Exception as e:  # upkie's own checks (e.g. MissingOptionalDependency, UpkieException)
        raise MotorlabError(f"cannot make {env_id}: {type(e).__name__}: {e}") from None
    if init_rand:
        try:
            env.unwrapped.update_init_rand(**init_rand)
        except TypeError as e:
            raise MotorlabError(f"init_rand: {e}; Upkie randomizes roll, pitch, x, z, omega_x, omega_y.") from None
    env = BalanceReward(env)
    if render_mode == "rgb_array":
        env = PyBulletCamera(env)
    elif render_mode is not None:
        raise MotorlabError(f"Upkie envs render only rgb_array (offscreen), not {render_mode!r}.")
    return env


# What the env processes' fork server imports once: each Upkie env beyond a process's first then
# starts in ~0.5 s instead of ~1.3 s (an evaluation builds one per episode of its batch).
PRELOAD = ("motorlab.envs", "motorlab.envs.upkie", "pybullet", "upkie.envs")


def make_upkie(env_id: str, render_mode: str | None = None, **kwargs: Any) -> gym.Env:
    """`build` in this process if no PyBullet env lives here yet, else in a child process."""
    register_upkie()
    import pybullet

    if not pybullet.isConnected(0):  # PyBullet reuses client 0 once it is disconnected
        return build(env_id, render_mode, kwargs)

    return ProcessEnv(functools.partial(build, env_id, render_mode, kwargs), preload=PRELOAD)
