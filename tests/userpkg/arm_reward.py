"""The user's torch reward and termination for ArmReach-v0 (userpkg/arm.py), for `--reward
userpkg.arm_reward:reward`, and a few broken ones for the error tests (tests/dynamics/test_rewards.py).

The planner's state is ArmReach's observation: joint angles (3), velocities (3), fingertip - target (2).
"""

import torch


def reward(obs, action, next_obs):
    """ArmReach-v0's own reward: distance to the target after the step, and a small control cost."""
    return -torch.linalg.vector_norm(next_obs[..., 6:8], dim=-1) - 0.01 * action.square().sum(-1)


def reached(obs, action, next_obs):
    """A termination: the fingertip within 2 cm of the target."""
    return torch.linalg.vector_norm(next_obs[..., 6:8], dim=-1) < 0.02


def reached_float(obs, action, next_obs):
    """The same termination as 0./1. floats."""
    return reached(obs, action, next_obs).float()


# ---- mistakes -----------------------------------------------------------------------------

def keepdim_reward(obs, action, next_obs):
    """Wrong shape: (..., 1) instead of (...,)."""
    return reward(obs, action, next_obs)[..., None]


def two_arguments(obs, action):
    """Wrong signature: no next_obs."""
    return -action.square().sum(-1)


def raises(obs, action, next_obs):
    return obs[..., 99]  # an index past the observation


def log_reward(obs, action, next_obs):
    """Non-finite on some states (log of a negative number)."""
    return torch.log(next_obs[..., 0])


def numpy_reward(obs, action, next_obs):
    """Not a torch tensor."""
    return reward(obs, action, next_obs).numpy()


def flat_reward(obs, action, next_obs):
    """Not batched over the leading dimensions: one number per row of a 2-d batch only."""
    return -next_obs.reshape(-1, next_obs.shape[-1]).square().sum(-1)


def distance_termination(obs, action, next_obs):
    """Not a termination: distances, not 0/1."""
    return torch.linalg.vector_norm(next_obs[..., 6:8], dim=-1)


NOT_A_FUNCTION = 0.5
