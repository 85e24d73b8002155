"""Reacher-v5's reward on observations, written as a user would: `--reward user_reacher_reward:reward`
(with benchmarks/ on the path). The same arithmetic as motorlab.dynamics.planner_rewards.reacher_obs_v5, so
benchmarks/mpc_reward.py can time a user's reward against the bundled one."""

import torch


def reward(obs: torch.Tensor, action: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
    """Minus the fingertip-to-target distance after the step (next_obs[8:10]), minus the squared action."""
    return -torch.linalg.vector_norm(next_obs[..., 8:10], dim=-1) - action.square().sum(-1)
