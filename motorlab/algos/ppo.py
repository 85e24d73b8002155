"""PPO (Stable-Baselines3): on-policy, any action space; the clip range is its own setting.

SB3 zips of A2C are recognised as PPO too: A2C's policy is PPO's ActorCriticPolicy, so its
exported policy acts and deploys as PPO's does.
"""

from motorlab.algos.base import OnPolicy, Preset

ALGORITHM = OnPolicy(
    name="ppo",
    title="PPO",
    summary="Proximal Policy Optimization (Stable-Baselines3), on-policy; Box, Discrete, MultiDiscrete or "
            "MultiBinary actions",
    cls="stable_baselines3:PPO",
    networks={"ActorCriticPolicy": "stable_baselines3.common.policies:ActorCriticPolicy",
              "MultiInputActorCriticPolicy": "stable_baselines3.common.policies:MultiInputActorCriticPolicy"},
    zip_modules=("stable_baselines3.common.policies", "stable_baselines3.ppo.policies",
                 "stable_baselines3.a2c.policies"),
    presets={
        "sb3-ppo": Preset("Stable-Baselines3's PPO defaults, named so recipes can say so", {"hyperparams": {}}),
        # PPO for MyoSuite's muscle tasks on a small machine, a contender of benchmarks/learner_per_hour.py:
        # K env processes feed one batched policy call per step, and an update (10 epochs of [256, 256]
        # networks over 2,048 steps) costs a fraction of the env steps' time, where SAC's one update per
        # step costs more than the step. Settings after rl-zoo3's MuJoCo PPO (normalized observations,
        # 10 epochs, GAE 0.95, linear learning rate).
        "sar-ppo": Preset(
            "PPO for muscle tasks on a small machine: 4 env processes, normalized observations, [256, 256]",
            {"n_envs": 4, "normalize": True, "lr": "linear:3e-4,0",
             "hyperparams": {"n_steps": 512, "batch_size": 256, "n_epochs": 10, "gamma": 0.99, "gae_lambda": 0.95,
                             "clip_range": 0.2, "ent_coef": 0.0,
                             "policy_kwargs": {"net_arch": {"pi": [256, 256], "vf": [256, 256]}}}}),
        # Upkie's own sim-to-real PPO balancer (upkie/ppo_balancer, settings.gin), as far as motorlab's
        # Upkie-PyBullet-Pendulum env allows: domain randomization (an action lag whose time constant is
        # drawn per episode from 0.05..0.15 s, Gaussian action and observation noise, random initial pitch,
        # velocity and pitch rate), 10 stacked observations, and its PPO settings (small networks, lr 3e-3,
        # clip 0.1). Its own wrappers also add the last action to the observation and bound the command's
        # rate of change; motorlab has neither. Upkie's training runs 2M steps; recipes run far fewer.
        "upkie-balancer": Preset(
            "Upkie's sim-to-real PPO balancer: domain randomization, 10 stacked observations, its PPO settings",
            {"lr": "3e-3", "clip_range": "0.1",
             "env": {"delay": "0.05..0.15", "delay_on": "action", "action_noise": 0.05, "obs_noise": 0.01,
                     "history": 10, "kwargs": {"init_rand": {"pitch": 0.25, "v_x": 0.1, "omega_y": 0.1}}},
             "hyperparams": {"n_steps": 2048, "batch_size": 64, "n_epochs": 10, "gae_lambda": 0.95, "ent_coef": 0.0,
                             "policy_kwargs": {"net_arch": {"pi": [16, 16], "vf": [32, 32]}}}}),
    },
)
