"""Make environments by id, with motorlab's wrappers applied in a fixed order:

    base env -> numerical guard -> reward shaping -> low-pass delay -> synergy actions -> observation history

Reward shaping sees the true state; the policy sees delayed, stacked observations.
Upkie ids (`Upkie-PyBullet-Pendulum`, ...) get motorlab's learning defaults and
balancing reward as their base env (see `motorlab.envs.upkie`). What motorlab knows about an env
family (falls, success, the extra that installs it, ...) is in `motorlab.envs.catalog`.
"""
from motorlab.envs.catalog import EnvFacts, facts, register_env
from motorlab.envs.config import (
    DISTURBANCES,
    ENV_KEYS,
    EnvConfig,
    EnvSettings,
    env_record,
    fold_env,
    given_env,
    is_bare,
    option_name,
    refuse_settings,
)
from motorlab.envs.ids import check_env_id, register_myosuite, register_robotics
from motorlab.envs.making import describe_env, early_end_label, env_dt, make_env, max_return, reads_observations
from motorlab.envs.wrappers import LowPassDelay, RewardShaping, delay_alpha

__all__ = ["EnvConfig", "EnvSettings", "ENV_KEYS", "DISTURBANCES", "describe_env", "make_env", "check_env_id", "max_return", "env_dt", "LowPassDelay", "RewardShaping",
           "delay_alpha", "register_myosuite", "register_robotics", "reads_observations", "early_end_label", "EnvFacts",
           "facts", "register_env", "fold_env", "given_env", "env_record", "is_bare", "option_name", "refuse_settings"]
