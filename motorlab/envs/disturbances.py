"""What real robots do to a policy, as Gymnasium wrappers: sensor and actuator noise, transport
latency, random pushes, and (MyoSuite) motor noise and muscle fatigue through MyoSuite's own
wrappers. The low-pass lag is `motorlab.envs.wrappers.LowPassDelay`.

Every amount is fixed (0.02) or a per-episode range ("0..0.02": domain randomization), drawn
uniformly at each reset. Draws come from a generator each wrapper seeds from the episode's reset
seed, not from the simulator's own: an episode is reproducible from its seed, episodes differ, and
adding noise leaves the env's own initial-state randomization untouched, so a robustness curve
compares policies from the same initial states at every noise level.
"""

from __future__ import annotations

from collections import deque
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from motorlab.errors import MotorlabError, did_you_mean

SPAN = ".."  # "LOW..HIGH": a per-episode range
PushDirection = Literal["horizontal", "x", "y", "z", "any"]
Fatigue = Literal["off", "fresh", "random"]

# MyoSuite's motor noise at scale 1: van Beers et al. (2004), the levels MyoSuite names
# (MotorNoiseCfg.van_beers_2004): signal-dependent std 0.103, constant std 0.185.
VAN_BEERS = (0.103, 0.185)


def env_dt_of(base_env) -> float | None:
    """Seconds per step of an unwrapped env: its `dt`, else MuJoCo timestep x frame skip."""
    dt = getattr(base_env, "dt", None)
    if dt is None:
        model = getattr(base_env, "mj_model", None) or getattr(base_env, "model", None)
        skip = getattr(base_env, "frame_skip", None)
        if model is not None and skip is not None and hasattr(model, "opt"):
            dt = float(model.opt.timestep) * int(skip)
    return float(dt) if dt is not None else None


# ---- amounts: a number, or a per-episode range ------------------------------------------------

def parse_span(value: Any, what: str, integer: bool = False, positive: bool = False) -> tuple[float, float]:
    """A fixed amount (0.2) or a per-episode range ("0.05..0.3", [0.05, 0.3]) as (low, high).

    Raises:
        MotorlabError: not a number or range, low above high, negative, or (integer) a fraction.
    """
    example = "2 or 0..3" if integer else "0.2 or 0.05..0.3"
    if isinstance(value, (list, tuple)) and len(value) == 2:
        low, high = value
    elif isinstance(value, str) and SPAN in value:
        low, _, high = value.partition(SPAN)
    else:
        low = high = value
    try:
        low, high = float(low), float(high)
    except (TypeError, ValueError):
        raise MotorlabError(f"{what} {value!r} is neither a number nor a range LOW..HIGH; write e.g. {example}.") \
            from None
    if not (np.isfinite(low) and np.isfinite(high)) or low < 0 or (positive and low <= 0 and low == high):
        raise MotorlabError(f"{what} {value!r} must be {'positive' if positive else 'zero or more'}; "
                            f"write e.g. {example}.")
    if low > high:
        raise MotorlabError(f"{what} range {value!r} runs backwards; write LOW..HIGH with LOW <= HIGH, e.g. {example}.")
    if integer and (low != int(low) or high != int(high)):
        raise MotorlabError(f"{what} {value!r} counts steps, so it takes whole numbers; write e.g. {example}.")
    return low, high


def span_text(value: Any) -> Any:
    """How a setting stores an amount: the number itself, or the range as "LOW..HIGH" (TOML-friendly)."""
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return f"{value[0]:g}{SPAN}{value[1]:g}"
    return value


class EpisodeRandom(gym.Wrapper):
    """A wrapper that draws from its own generator, seeded from each reset seed (see the module doc).

    Reset without a seed continues the stream (SB3's vectorized envs seed only the first reset), so
    training episodes differ; an evaluation episode, reset with its own seed, repeats exactly.
    """

    SALT = 0  # each kind of wrapper its own stream, so two wrappers never draw the same numbers

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.rng: np.random.Generator | None = None

    def _seed(self, kwargs: dict[str, Any]) -> None:
        seed = kwargs.get("seed")
        if seed is not None:
            self.rng = np.random.default_rng([int(seed), self.SALT])
        elif self.rng is None:
            self.rng = np.random.default_rng()  # unseeded, as Gymnasium does for an unseeded env

    def draw(self, span: tuple[float, float], integer: bool = False) -> float:
        low, high = span
        if low == high:
            return low
        return float(self.rng.integers(int(low), int(high) + 1)) if integer else float(self.rng.uniform(low, high))


def record_draws(info: dict, **drawn: Any) -> dict:
    """The episode's drawn amounts in the reset info (under "disturbances"), for logs and tests."""
    info.setdefault("disturbances", {}).update(drawn)
    return info


# ---- sensor and actuator noise ----------------------------------------------------------------

def noise_std(value: Any, size: int, what: str) -> tuple[float, float] | np.ndarray:
    """A noise setting as a (low, high) range of one std for every element, or (a list) one std per element."""
    if isinstance(value, (list, tuple)):
        if len(value) != size:
            raise MotorlabError(f"{what} has {len(value)} values but there are {size} elements; give one std "
                                f"(e.g. 0.01), a range (0..0.02) or exactly {size} values.")
        std = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(std)) or np.any(std < 0):
            raise MotorlabError(f"{what} {list(value)!r}: every std must be zero or more.")
        return std
    return parse_span(value, what)


class GaussianNoise(EpisodeRandom, gym.utils.RecordConstructorArgs):
    """Zero-mean Gaussian noise on what the policy sees and/or what it commands.

    Observation noise is added to each observation the policy receives (the env's state is not
    touched); action noise is added to the command before the env gets it, then clipped into the
    action space. A std is one number for every element, a range drawn once per episode, or one
    std per element.
    """

    SALT = 1

    def __init__(self, env: gym.Env, obs_std: Any = None, action_std: Any = None):
        gym.utils.RecordConstructorArgs.__init__(self, obs_std=obs_std, action_std=action_std)
        super().__init__(env)
        obs_size = int(np.prod(env.observation_space.shape))
        act_size = int(np.prod(env.action_space.shape))
        self.obs_std = None if obs_std is None else noise_std(obs_std, obs_size, "observation noise")
        self.action_std = None if action_std is None else noise_std(action_std, act_size, "action noise")
        self._obs_now: Any = 0.0
        self._act_now: Any = 0.0

    def _episode_std(self, std) -> Any:
        return std if isinstance(std, np.ndarray) else self.draw(std)

    def reset(self, **kwargs: Any):
        self._seed(kwargs)
        obs, info = self.env.reset(**kwargs)
        drawn = {}
        if self.obs_std is not None:
            self._obs_now = self._episode_std(self.obs_std)
            drawn["obs_noise"] = self._obs_now
        if self.action_std is not None:
            self._act_now = self._episode_std(self.action_std)
            drawn["action_noise"] = self._act_now
        return self._noisy(obs), record_draws(info, **drawn)

    def _noisy(self, obs):
        if self.obs_std is None:
            return obs
        obs = np.asarray(obs)
        std = np.reshape(self._obs_now, obs.shape) if np.ndim(self._obs_now) else self._obs_now
        return (obs + std * self.rng.standard_normal(obs.shape)).astype(obs.dtype)

    def step(self, action):
        if self.action_std is not None:
            space = self.env.action_space  # a Box: make_env refuses action noise on other actions
            action = np.asarray(action, dtype=space.dtype)
            std = np.reshape(self._act_now, action.shape) if np.ndim(self._act_now) else self._act_now
            noise = std * self.rng.standard_normal(action.shape)
            action = np.clip(action + noise, space.low, space.high).astype(space.dtype)
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.action_std is not None:
            info["applied_action"] = np.array(action, copy=True)
        return self._noisy(obs), reward, terminated, truncated, info


# ---- transport latency ------------------------------------------------------------------------

class Latency(EpisodeRandom, gym.utils.RecordConstructorArgs):
    """Transport latency of k whole steps: the env gets the command from k steps ago (the rest
    action until then), and/or the policy sees the observation from k steps ago (the first one until
    then). Unlike the low-pass lag, nothing of the signal arrives early; k may be a per-episode range.
    """

    SALT = 2

    def __init__(self, env: gym.Env, steps: Any, on: str = "both"):
        gym.utils.RecordConstructorArgs.__init__(self, steps=steps, on=on)
        super().__init__(env)
        if on not in ("action", "observation", "both"):
            raise MotorlabError(f"latency must act on 'action', 'observation' or 'both', got {on!r}.")
        self.steps = parse_span(steps, "latency (steps)", integer=True)
        self.on = on
        space = env.action_space
        if on in ("action", "both") and not isinstance(space, gym.spaces.Box):
            raise MotorlabError("a latency on actions needs a continuous (Box) action space; give --latency-on "
                                "observation.")
        # the command held until the first one arrives: zero, clipped into the box (Box actions only)
        self._rest = (np.clip(np.zeros(space.shape), space.low, space.high).astype(space.dtype)
                      if isinstance(space, gym.spaces.Box) else np.zeros(0))
        self.k = 0
        self._actions: deque = deque()
        self._observations: deque = deque()

    def reset(self, **kwargs: Any):
        self._seed(kwargs)
        obs, info = self.env.reset(**kwargs)
        self.k = int(self.draw(self.steps, integer=True))
        self._actions = deque([self._rest.copy() for _ in range(self.k)])
        self._observations = deque([np.array(obs, copy=True) for _ in range(self.k)])
        return obs, record_draws(info, latency=self.k)

    def step(self, action):
        if self.on in ("action", "both"):
            self._actions.append(np.array(action, copy=True))
            action = self._actions.popleft()
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.on in ("observation", "both"):
            self._observations.append(np.array(obs, copy=True))
            obs = self._observations.popleft()
        info["applied_action"] = np.array(action, copy=True)
        return obs, reward, terminated, truncated, info


# ---- random pushes ----------------------------------------------------------------------------

def mujoco_model_data(env: gym.Env) -> tuple[Any, Any]:
    """The MjModel and MjData of a MuJoCo env (Gymnasium's or MyoSuite's), else (None, None)."""
    import mujoco

    base = env.unwrapped
    model = getattr(base, "mj_model", None) or getattr(base, "model", None)
    data = getattr(base, "mj_data", None) or getattr(base, "data", None)
    return (model, data) if isinstance(model, mujoco.MjModel) else (None, None)


class RandomPush(EpisodeRandom, gym.utils.RecordConstructorArgs):
    """External forces on a named body at random times (MuJoCo's `xfrc_applied`, at the body's
    centre of mass), like a hand shoving the robot.

    The time between the starts of two pushes is drawn from `interval` (seconds); each push lasts
    `duration` seconds (default: one env step, an impulse of force x dt) with a magnitude drawn from
    `force` (newtons) in a random direction: in the horizontal plane, along one world axis (either
    sign), or anywhere. The step's force is in `info["push_force"]`.
    """

    SALT = 3

    def __init__(self, env: gym.Env, body: str, force: Any, interval: Any = "1..3", duration: float | None = None,
                 direction: PushDirection = "horizontal"):
        gym.utils.RecordConstructorArgs.__init__(self, body=body, force=force, interval=interval, duration=duration,
                                                 direction=direction)
        super().__init__(env)
        import mujoco

        self.model, self.data = mujoco_model_data(env)
        name = env.spec.id if env.spec else type(env.unwrapped).__name__
        if self.model is None:
            raise MotorlabError(f"pushes act on a MuJoCo body, and {name} is not a MuJoCo env; drop --push-body.")
        self.body = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, body)
        if self.body < 0:
            bodies = [self.model.body(i).name for i in range(1, self.model.nbody)]
            raise MotorlabError(f"push body {body!r} is not in {name}'s model{did_you_mean(body, bodies)}; its bodies: "
                                f"{', '.join(bodies[:30])}{' ...' if len(bodies) > 30 else ''}.")
        if direction not in ("horizontal", "x", "y", "z", "any"):
            raise MotorlabError(f"push direction {direction!r}: choose horizontal, x, y, z or any.")
        self.force = parse_span(force, "push force (N)")
        self.interval = parse_span(interval, "push interval (s)", positive=True)
        self.dt = float(env_dt_of(env.unwrapped) or self.model.opt.timestep)
        if duration is not None and (not np.isfinite(duration) or duration <= 0):
            raise MotorlabError(f"push duration {duration!r} must be a positive number of seconds.")
        self.duration_steps = 1 if duration is None else max(1, round(duration / self.dt))
        self.direction = direction
        self._t = 0
        self._next = 0
        self._left = 0
        self._force = np.zeros(3)

    def _next_start(self) -> int:
        return self._t + max(1, round(self.draw(self.interval) / self.dt))

    def _unit(self) -> np.ndarray:
        if self.direction in ("x", "y", "z"):
            unit = np.zeros(3)
            unit["xyz".index(self.direction)] = self.rng.choice([-1.0, 1.0])
            return unit
        v = self.rng.normal(size=3)
        if self.direction == "horizontal":
            v[2] = 0.0
        return v / max(np.linalg.norm(v), 1e-12)

    def reset(self, **kwargs: Any):
        self._seed(kwargs)
        obs, info = self.env.reset(**kwargs)
        self.data.xfrc_applied[self.body, :] = 0.0
        self._t, self._left = 0, 0
        self._next = self._next_start()
        return obs, info

    def step(self, action):
        if self._left == 0 and self._t >= self._next:  # a new push starts
            self._force = self.draw(self.force) * self._unit()
            self._left = self.duration_steps
        pushing = self._left > 0
        self.data.xfrc_applied[self.body, :3] = self._force if pushing else 0.0
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["push_force"] = self._force.copy() if pushing else np.zeros(3)
        self._t += 1
        if pushing:
            self._left -= 1
            if self._left == 0:
                self.data.xfrc_applied[self.body, :3] = 0.0
                self._next = self._next_start()
        return obs, reward, terminated, truncated, info


# ---- MyoSuite: motor noise and fatigue, through MyoSuite's own wrappers -----------------------

def _myosuite_stage(env: gym.Env, what: str, make):
    """Install one of MyoSuite's muscle wrappers, or say in one line why it cannot be."""
    if not getattr(env.unwrapped, "supports_ctrl_stages", False):
        name = env.spec.id if env.spec else type(env.unwrapped).__name__
        raise MotorlabError(f"{what} acts on MyoSuite's muscles, and {name} has none that MyoSuite can reach; "
                            "for other envs use --action-noise.")
    try:
        return make()
    except ValueError as e:  # a myoFati* id already has its fatigue stage
        raise MotorlabError(f"{what}: {e}") from None


class MotorNoise(EpisodeRandom, gym.utils.RecordConstructorArgs):
    """MyoSuite's motor noise on the muscle excitations (myosuite.envs.wrappers.MotorNoiseWrapper),
    at `scale` x van Beers et al. (2004): signal-dependent std 0.103 u + constant std 0.185, scaled.
    MyoSuite draws the noise from the env's seeded generator; a range draws the scale per episode."""

    SALT = 4

    def __init__(self, env: gym.Env, scale: Any):
        gym.utils.RecordConstructorArgs.__init__(self, scale=scale)
        from myosuite.envs.wrappers import MotorNoiseWrapper

        super().__init__(_myosuite_stage(env, "motor noise", lambda: MotorNoiseWrapper(env, None)))
        self.scale = parse_span(scale, "motor noise (x van Beers 2004)")

    def reset(self, **kwargs: Any):
        self._seed(kwargs)
        scale = self.draw(self.scale)
        self.env.set_motor_noise({"signal_dependent_std": VAN_BEERS[0] * scale, "constant_std": VAN_BEERS[1] * scale})
        obs, info = self.env.reset(**kwargs)
        return obs, record_draws(info, motor_noise=scale)


def muscle_fatigue(env: gym.Env, mode: Fatigue) -> gym.Env:
    """MyoSuite's 3CC-r muscle fatigue (myosuite.envs.wrappers.FatigueWrapper): muscles start each
    episode rested ("fresh") or with a random fatigue state ("random")."""
    from myosuite.envs.wrappers import FatigueWrapper

    return _myosuite_stage(env, "muscle fatigue", lambda: FatigueWrapper(env, fatigue_reset_random=mode == "random"))
