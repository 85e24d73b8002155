"""make_env: an env by id, with motorlab's wrappers applied in a fixed order (see motorlab.envs), and
what a run reads of an env (its dt, its best return, how an episode ends early)."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym

from motorlab.envs.catalog import facts
from motorlab.envs.config import EnvConfig
from motorlab.envs.disturbances import (
    GaussianNoise,
    Latency,
    MotorNoise,
    RandomPush,
    muscle_fatigue,
)
from motorlab.envs.ids import check_env_id, route_mujoco_warnings
from motorlab.envs.rewards import resolve_reward
from motorlab.envs.spaces import check_spaces, is_dict, obs_layout, require_actions
from motorlab.envs.upkie import make_upkie
from motorlab.envs.wrappers import (
    EpisodeCap,
    LowPassDelay,
    NumericalGuard,
    RewardShaping,
    env_dt_of,
    has_time_limit,
    user_code_error,
)
from motorlab.errors import MotorlabError
from motorlab.user_modules import (
    split_env_id,
    user_env_ids,
)

_checked: set[str] = set()  # user env ids Gymnasium's checker passed in this process


def check_user_env(env: gym.Env, env_id: str) -> None:
    """Gymnasium's env checker, once per process, on an env a user's module registered: spaces,
    reset and step signatures, observations inside their space, seeding. A rejected env stops
    here with the checker's message instead of deep inside training.

    Raises:
        MotorlabError: the checker's first complaint.
    """
    if env_id in _checked:
        return
    from gymnasium.utils.env_checker import check_env

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its advice (float32, bounds) is not an error
            check_env(env.unwrapped, skip_render_check=True)
    except Exception as e:  # the checker asserts, and the env's own code may raise anything
        message = " ".join(str(e).split()) or type(e).__name__
        raise MotorlabError(f"{env_id}: Gymnasium's env checker rejects it: {message}") from None
    _checked.add(env_id)


# Steps an episode of an env without a time limit may run before the run stops with one line
# saying how to give it one (--env-arg max_episode_steps=N): an env that ends its episodes itself
# runs as it is, one that never ends no longer hangs evaluation.
UNLIMITED_EPISODE_CAP = 100_000


def make_env(cfg: EnvConfig, shaped: bool = True, render_mode: str | None = None, dict_obs: bool = False,
             **kwargs: Any) -> gym.Env:
    """Build the env described by `cfg`.

    Args:
        cfg: env id and wrappers.
        shaped: apply reward shaping (evaluation passes False to report the task's return).
        render_mode: passed to `gymnasium.make` (e.g. "rgb_array" for videos).
        dict_obs: keep a Dict observation space as it is (SB3 training: MultiInputPolicy, HER),
            unless a wrapper that reads observations as one array is asked for (a delay or latency
            on observations, observation noise, history, a reward shaping that reads the
            observation). Otherwise a Dict observation is flattened
            as `gymnasium.spaces.flatten` does (motorlab.envs.spaces: the layout of its keys).

    An env with no time limit (no max_episode_steps) gets `EpisodeCap`: an episode past
    UNLIMITED_EPISODE_CAP steps stops the run with one line; `--env-arg max_episode_steps=N`
    gives it Gymnasium's TimeLimit. What the env (or a --reward function) raises while it runs is
    one MotorlabError line naming it, the exception and where (`wrappers.user_code_error`).

    Raises:
        MotorlabError: unknown id, bad delay, unknown reward, an env that cannot render (with
            render_mode), a setting that acts on Box actions on an env whose actions are not,
            observations no motorlab policy reads or actions none acts in (`spaces.check_spaces`).
    """
    route_mujoco_warnings()
    check_env_id(cfg.id)
    name = split_env_id(cfg.id)[1]
    if facts(cfg.id).extra == "upkie":
        env = make_upkie(cfg.id, render_mode, **{**cfg.kwargs, **kwargs})
    else:
        env = _gym_make(cfg, name, render_mode, kwargs)
        if name in user_env_ids():
            check_user_env(env, cfg.id)
    try:
        check_spaces(env, cfg.id)  # what no motorlab policy reads or acts in: refused at every kind's door
        _require_box_wrappers(env, cfg)
    except MotorlabError:
        env.close()
        raise
    if not has_time_limit(env) and facts(cfg.id).extra != "upkie":  # Upkie's envs end on their time_limit
        env = EpisodeCap(env, cfg.id, UNLIMITED_EPISODE_CAP)
    if cfg.motor_noise is not None:
        env = MotorNoise(env, cfg.motor_noise)  # MyoSuite's own wrappers, on the muscle excitations
    if cfg.fatigue != "off":
        env = muscle_fatigue(env, cfg.fatigue)
    env = NumericalGuard(env, cfg.id)  # also: the env's own exceptions as one line naming it
    if is_dict(env.observation_space) and not (dict_obs and not reads_observations(cfg)):
        obs_layout(env.observation_space)  # Box entries only: one line naming the key otherwise
        env = gym.wrappers.FlattenObservation(env)
    if shaped and cfg.reward and cfg.reward != "task":
        env = RewardShaping(env, resolve_reward(cfg.reward), name=cfg.reward)
    if cfg.push_body:
        env = RandomPush(env, cfg.push_body, cfg.push_force, cfg.push_interval, cfg.push_duration, cfg.push_direction)
    if cfg.delay:
        env = LowPassDelay(env, cfg.delay, on=cfg.delay_on)
    if cfg.latency:
        env = Latency(env, cfg.latency, on=cfg.latency_on)
    if cfg.obs_noise is not None or cfg.action_noise is not None:
        env = GaussianNoise(env, cfg.obs_noise, cfg.action_noise)
    if cfg.sar:
        from motorlab.synergies.wrapper import SynergyActionWrapper

        env = SynergyActionWrapper(env, cfg.sar, cfg.phi)  # outside the delay: muscles are what lags
    if cfg.history > 1:
        env = gym.wrappers.FrameStackObservation(env, cfg.history, padding_type="reset")
        env = gym.wrappers.FlattenObservation(env)
    return env


def _gym_make(cfg: EnvConfig, name: str, render_mode: str | None, kwargs: dict[str, Any]) -> gym.Env:
    """`gymnasium.make`, its mistakes in one line: an argument the env does not take, an env that
    cannot render, a Gymnasium-Robotics model that fails to build under this MuJoCo."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # -v4 deprecation notices are noise here
        try:
            # render_mode only when asked: a user's env need not take the argument
            rendering = {"render_mode": render_mode} if render_mode is not None else {}
            return gym.make(name, **rendering, **cfg.kwargs, **kwargs)
        except TypeError as e:  # an env argument it does not take
            if render_mode is not None and "render_mode" in str(e):
                raise MotorlabError(f"{cfg.id} cannot render: it takes no render_mode argument. A video needs a "
                                    "MuJoCo env, or an env that takes render_mode='rgb_array' and returns frames "
                                    "from render().") from None
            raise MotorlabError(f"{cfg.id} does not take these settings: {e}.") from None
        except AssertionError as e:
            if not facts(name).broken:
                raise user_code_error(f"making {cfg.id}", e) from None
            import mujoco

            raise MotorlabError(f"{cfg.id} fails to build inside Gymnasium-Robotics with MuJoCo {mujoco.__version__} "
                                "(an upstream incompatibility of its Fetch, Shadow-hand and Kitchen models); "
                                "its mazes (PointMaze_*, AntMaze_*) and the Adroit hand (AdroitHand*) work.") from None
        except MotorlabError:
            raise
        except Exception as e:  # the env's constructor (often a user's) may raise anything
            raise user_code_error(f"making {cfg.id}", e) from None


def _require_box_wrappers(env: gym.Env, cfg: EnvConfig) -> None:
    """Refuse, in one line, the settings that act on Box actions when the env's actions are not."""
    on_actions = ("action", "both")
    uses = [("--delay on actions", bool(cfg.delay) and cfg.delay_on in on_actions, "give --delay-on observation"),
            ("--latency on actions", bool(cfg.latency) and cfg.latency_on in on_actions,
             "give --latency-on observation"),
            ("--action-noise", cfg.action_noise is not None, "drop it"),
            ("--sar (synergy actions)", bool(cfg.sar), "drop it")]
    for user, used, instead in uses:
        if used:
            require_actions(env.action_space, user, instead=instead, env_id=cfg.id)


# Reward shapings that never look at the observation (the others are given one array)
OBS_FREE_REWARDS = (None, "task", "alive", "action-penalty")


def reads_observations(cfg: EnvConfig) -> bool:
    """Whether a wrapper `cfg` asks for works on the observation as one array (a Dict one is then
    flattened first, even for training)."""
    on_obs = ("observation", "both")
    return bool((cfg.delay and cfg.delay_on in on_obs) or (cfg.latency and cfg.latency_on in on_obs)
                or cfg.obs_noise is not None or cfg.history > 1 or cfg.reward not in OBS_FREE_REWARDS)


def describe_env(env: EnvConfig) -> str:
    """The env and its wrappers in a few words: "InvertedPendulum-v5, delay 0.2 s on both, history 10"."""
    tags = [env.id]
    if env.delay:
        tags.append(f"delay {env.delay} s on {env.delay_on}")  # action, observation or both
    if env.latency:
        tags.append(f"latency {env.latency} steps on {env.latency_on}")
    for key, unit in (("obs_noise", "observation noise std"), ("action_noise", "action noise std"),
                      ("motor_noise", "motor noise x")):
        value = getattr(env, key)
        if value is not None:
            tags.append(f"{unit} {','.join(f'{v:g}' for v in value) if isinstance(value, list) else value}")
    if env.push_body:
        tags.append(f"pushes on {env.push_body}: {env.push_force} N every {env.push_interval} s")
    if env.fatigue != "off":
        tags.append(f"muscle fatigue ({env.fatigue})")
    if env.history > 1:
        tags.append(f"history {env.history}")
    if env.sar:
        tags.append(f"synergies {Path(env.sar).name}, phi {env.phi:g}")
    return ", ".join(tags)


def env_dt(env: gym.Env) -> float | None:
    """Seconds per env step: `dt` where the env has one (Gymnasium MuJoCo envs), else
    MuJoCo's timestep times the frame skip (MyoSuite)."""
    return env_dt_of(env.unwrapped)


def max_return(env_id: str) -> float | None:
    """The best return an episode can reach, where the task defines one.

    The catalogue's `max_return` (a number, or the time limit where the reward is +1 per step
    alive: InvertedPendulum's 1000); otherwise the env's registered reward threshold, else None.
    """
    check_env_id(env_id)
    spec = gym.spec(split_env_id(env_id)[1])
    best = facts(env_id).max_return
    if best == "time_limit":
        if spec.max_episode_steps:
            return float(spec.max_episode_steps)
    elif best is not None:
        return float(best)
    return float(spec.reward_threshold) if spec.reward_threshold is not None else None


def early_end_label(env_id: str) -> str:
    """What reports call episodes of this env that ended before the time limit: "falls" where the
    catalogue says an early end is a fall (the pole or the body fell), else "ended early"."""
    return facts(env_id).early_end
