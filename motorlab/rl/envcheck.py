"""What a training run needs of its env, checked before anything is written: the algorithm fits
the env's action space, and hindsight relabelling (--her) has goals to relabel.

    actions         those the algorithm declares (algos/<name>.py: Box only, or also
                    Discrete, MultiDiscrete, MultiBinary for PPO and RecurrentPPO)
    observations    a Dict one only for an algorithm with a multi-input policy
    --her           an algorithm that takes it (rl.config), a goal-conditioned env (motorlab.envs.spaces.is_goal_conditioned)
                    whose Dict observation reaches the replay buffer as it is, and the env's own reward
                    (HER recomputes rewards with the env's compute_reward)

Each refusal is one line naming the space and what fits it.
"""

from __future__ import annotations

import gymnasium as gym

from motorlab import algos
from motorlab.envs import EnvConfig, make_env, reads_observations
from motorlab.envs.spaces import describe_space, is_dict, is_goal_conditioned
from motorlab.errors import MotorlabError
from motorlab.rl.config import TrainConfig


def check_train_env(cfg: TrainConfig) -> None:
    """Build the training env once and check it against the settings.

    Raises:
        MotorlabError: a bad env setting (from make_env), an algorithm that cannot act in the env's
            action space, --her where it cannot relabel.
    """
    algo = algos.get(cfg.algo)
    env = make_env(cfg.env, dict_obs=algo.dict_obs)  # the observation training sees
    try:
        check_actions(cfg, env.action_space)
        if algo.sb3:
            algo.policy(is_dict(env.observation_space), cfg.env.id)  # a Dict observation needs a multi-input policy
        if cfg.her:
            check_her(cfg.env, env)
    finally:
        env.close()


def check_actions(cfg: TrainConfig, space: gym.Space) -> None:
    """One line naming the space and the algorithms that fit it, when `cfg.algo` does not (the algorithm's
    own declaration: motorlab.algos.base.Algorithm.check_actions)."""
    algos.get(cfg.algo).check_actions(space, cfg.env.id)


def check_her(env_cfg: EnvConfig, env: gym.Env) -> None:
    """--her needs the goals: a goal-conditioned env, its Dict observation kept whole, its own reward."""
    base = env.unwrapped
    if not is_goal_conditioned(base):
        raise MotorlabError(f"--her needs a goal-conditioned env (a Dict observation with achieved_goal and "
                            f"desired_goal, and compute_reward), and {env_cfg.id}'s observations are "
                            f"{describe_space(base.observation_space)}; drop --her.")
    if env_cfg.reward not in (None, "task"):
        raise MotorlabError(f"--her recomputes the rewards of relabelled goals with the env's compute_reward, so "
                            f"--reward {env_cfg.reward} would apply to some transitions only; drop --reward or --her.")
    if reads_observations(env_cfg):
        raise MotorlabError(f"--her relabels the goals inside the Dict observation, and {flattening(env_cfg)} "
                            "turns it into one array; drop it or --her.")


def flattening(env_cfg: EnvConfig) -> str:
    """The settings that make training flatten a Dict observation, as the user gave them."""
    on_obs = ("observation", "both")
    given = [(f"--history {env_cfg.history}", env_cfg.history > 1),
             ("--obs-noise", env_cfg.obs_noise is not None),
             ("--delay on observations", bool(env_cfg.delay) and env_cfg.delay_on in on_obs),
             ("--latency on observations", bool(env_cfg.latency) and env_cfg.latency_on in on_obs)]
    return ", ".join(name for name, used in given if used) or "an env setting"
