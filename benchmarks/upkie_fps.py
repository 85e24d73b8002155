"""PPO training throughput on Upkie-PyBullet-Pendulum: K = 1 and K = 2 parallel envs
(motorlab's defaults: headless, unthrottled, 200 Hz), and the same PPO on the env as
Upkie itself makes it (`gymnasium.make(id, gui=False)`: the loop regulated to real
time), all in one run.

fps = env steps / seconds inside SB3's learn() (rollouts and updates; no evaluation),
with SB3's PPO defaults (n_steps 2048 per env, batch 64, 10 epochs). K = 1 steps the
env in this process (DummyVecEnv); K = 2 in two subprocesses (SubprocVecEnv).

Usage:  .venv/bin/python benchmarks/upkie_fps.py [--steps 16384] [--reference-steps 2048]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

ENV_ID = "Upkie-PyBullet-Pendulum"


def motorlab_fps(n_envs: int, steps: int) -> float:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    from motorlab.envs import EnvConfig, make_env

    torch.set_num_threads(1)
    cfg = EnvConfig(id=ENV_ID)
    venv = make_vec_env(lambda: make_env(cfg), n_envs=n_envs, seed=0,
                        vec_env_cls=SubprocVecEnv if n_envs > 1 else DummyVecEnv)
    model = PPO("MlpPolicy", venv, seed=0, device="cpu", verbose=0)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    seconds = time.perf_counter() - t0
    venv.close()
    return model.num_timesteps / seconds


def upkie_default_fps(steps: int) -> float:
    """SB3 PPO on the env with Upkie's own settings (frequency regulated to 200 Hz real time)."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO

    from motorlab.envs.upkie import register_upkie

    torch.set_num_threads(1)
    register_upkie()
    env = gym.make(ENV_ID, gui=False, max_episode_steps=2000)
    model = PPO("MlpPolicy", env, seed=0, device="cpu", verbose=0, n_steps=steps)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    seconds = time.perf_counter() - t0
    env.close()
    return model.num_timesteps / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=16384, help="env steps per motorlab measurement")
    parser.add_argument("--reference-steps", type=int, default=2048, help="env steps for Upkie's real-time default")
    args = parser.parse_args()
    recorder = Recorder("upkie_fps")  # the git state and load, read as the run starts
    k1 = motorlab_fps(1, args.steps)
    print(f"K=1: {k1:,.0f} steps/s", file=sys.stderr)
    k2 = motorlab_fps(2, args.steps)
    print(f"K=2: {k2:,.0f} steps/s", file=sys.stderr)
    ref = upkie_default_fps(args.reference_steps)
    print(f"Upkie defaults: {ref:,.0f} steps/s", file=sys.stderr)
    recorder.record({
        "env": ENV_ID,
        "cores": os.cpu_count(),
        "steps": args.steps,
        "motorlab_k1_fps": round(k1, 1),
        "motorlab_k2_fps": round(k2, 1),
        "scaling_k2_over_k1": round(k2 / k1, 3),
        "upkie_defaults_fps": round(ref, 1),
        "speedup_k2_over_upkie_defaults": round(k2 / ref, 2),
    })


if __name__ == "__main__":
    main()
