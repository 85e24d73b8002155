"""Make environments by id, with motorlab's wrappers applied in a fixed order:

    base env -> numerical guard -> reward shaping -> low-pass delay -> synergy actions -> observation history

Reward shaping sees the true state; the policy sees delayed, stacked observations.
Upkie ids (`Upkie-PyBullet-Pendulum`, ...) get motorlab's learning defaults and
balancing reward as their base env (see `motorlab.envs.upkie`).
"""

from __future__ import annotations

import logging
import warnings
from typing import Any, Literal

import gymnasium as gym
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, field_validator

from motorlab.envs.rewards import resolve_reward
from motorlab.envs.upkie import is_upkie, make_upkie, register_upkie
from motorlab.envs.wrappers import DelayOn, LowPassDelay, NumericalGuard, RewardShaping, delay_alpha, env_dt_of
from motorlab.errors import MotorlabError, did_you_mean

__all__ = ["EnvConfig", "make_env", "check_env_id", "max_return", "env_dt", "LowPassDelay", "RewardShaping",
           "delay_alpha", "register_myosuite"]

def _route_mujoco_warnings() -> None:
    """Send MuJoCo's C-level warnings to Python logging instead of stderr and a
    MUJOCO_LOG.TXT in the working directory. MyoSuite models warn on every load;
    instabilities are still counted from mjData.warning by NumericalGuard."""
    import mujoco

    log = logging.getLogger("motorlab.mujoco")
    mujoco.set_mju_user_warning(lambda message: log.debug("MuJoCo: %s", message.strip()))


_route_mujoco_warnings()

# Envs whose reward is +1 per step alive: the maximum return is the time limit.
_ALIVE_REWARD_PREFIXES = ("InvertedPendulum-",)


class EnvConfig(BaseModel):
    """Which env, and how it is wrapped."""

    model_config = ConfigDict(extra="forbid")

    id: str = "InvertedPendulum-v5"
    delay: float | None = Field(None, description="low-pass time constant in seconds (None: no delay)")
    # Actuation and perception delay, as in the robust-policy workflow (DESIGN.md).
    delay_on: DelayOn = "both"
    history: int = Field(1, ge=1, description="observation frames stacked (1: no history)")
    reward: str | None = Field(None, description="built-in reward name or module:function")
    sar: str | None = Field(None, description="sar.npz: act in synergy space (SynergyActionWrapper)")
    phi: float = Field(1.0, gt=0, le=1, description="synergy weight: 1 = synergies only, <1 = blend with raw actions")
    kwargs: dict[str, Any] = Field(default_factory=dict,
                                   description="keyword arguments for the env (gymnasium.make), e.g. Upkie's time_limit")
    # How an episode's success is read from the env's per-step flag (info["solved"]): "any" step
    # (manipulation: the object reached its goal once), or the "final" step (walking: upright and
    # at the commanded speed when the episode ended). "auto" picks final for MyoSuite's walking
    # tasks, whose flag is a state, not an event: under "any", even a policy that falls forward
    # is counted as walking once (see motorlab.evaluate.success_mode).
    success: Literal["auto", "any", "final"] = "auto"

    @field_validator("sar")
    @classmethod
    def _absolute(cls, v):
        # run folders record where the SAR is, wherever the run is evaluated from
        return str(Path(v).resolve()) if v else v


def register_myosuite() -> bool:
    """Import MyoSuite, which registers its env ids (myoHandReorient8-v0, myoLegWalk-v0, ...).

    Returns:
        False when MyoSuite is not installed.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import myosuite  # noqa: F401  (import registers the envs)
    except ImportError:
        return False
    return True


def check_env_id(env_id: str) -> None:
    """Raise a clear error for an env id Gymnasium does not know, with close matches.

    MyoSuite ids (`myo...`) are registered on first use; without MyoSuite installed
    they get a message saying how to install it.
    """
    if is_upkie(env_id):
        register_upkie()  # clear message when upkie or pybullet is missing
    if env_id not in gym.registry:
        installed = register_myosuite()
        if env_id in gym.registry:
            return
        if env_id.startswith("myo") and not installed:
            raise MotorlabError(
                f"{env_id} is a MyoSuite env, and MyoSuite is not installed: "
                "`pip install myosuite==3.0.0` (make demo / make test install it)."
            )
        raise MotorlabError(
            f"unknown env id {env_id!r}{did_you_mean(env_id, gym.registry.keys())}; "
            "`python -c \"import gymnasium; gymnasium.pprint_registry()\"` lists the ids."
        )


def make_env(cfg: EnvConfig, shaped: bool = True, render_mode: str | None = None, **kwargs: Any) -> gym.Env:
    """Build the env described by `cfg`.

    Args:
        cfg: env id and wrappers.
        shaped: apply reward shaping (evaluation passes False to report the task's return).
        render_mode: passed to `gymnasium.make` (e.g. "rgb_array" for videos).

    Raises:
        MotorlabError: unknown id, bad delay, unknown reward.
    """
    check_env_id(cfg.id)
    if is_upkie(cfg.id):
        env = make_upkie(cfg.id, render_mode, **{**cfg.kwargs, **kwargs})
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # -v4 deprecation notices are noise here
            try:
                env = gym.make(cfg.id, render_mode=render_mode, **cfg.kwargs, **kwargs)
            except TypeError as e:  # an env argument it does not take
                raise MotorlabError(f"{cfg.id} does not take these settings: {e}.") from None
    env = NumericalGuard(env)
    if shaped and cfg.reward and cfg.reward != "task":
        env = RewardShaping(env, resolve_reward(cfg.reward), name=cfg.reward)
    if cfg.delay:
        env = LowPassDelay(env, cfg.delay, on=cfg.delay_on)
    if cfg.sar:
        from motorlab.synergy.wrapper import SynergyActionWrapper

        env = SynergyActionWrapper(env, cfg.sar, cfg.phi)  # outside the delay: muscles are what lags
    if cfg.history > 1:
        env = gym.wrappers.FrameStackObservation(env, cfg.history, padding_type="reset")
        env = gym.wrappers.FlattenObservation(env)
    return env


def env_dt(env: gym.Env) -> float | None:
    """Seconds per env step: `dt` where the env has one (Gymnasium MuJoCo envs), else
    MuJoCo's timestep times the frame skip (MyoSuite)."""
    return env_dt_of(env.unwrapped)


def max_return(env_id: str) -> float | None:
    """The best return an episode can reach, where the task defines one.

    InvertedPendulum pays +1 per step, so it is the time limit (1000);
    otherwise the env's registered reward threshold, else None.
    """
    check_env_id(env_id)
    spec = gym.spec(env_id)
    if env_id.startswith(_ALIVE_REWARD_PREFIXES) and spec.max_episode_steps:
        return float(spec.max_episode_steps)
    return float(spec.reward_threshold) if spec.reward_threshold is not None else None
