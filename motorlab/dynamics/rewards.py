"""Env rewards in torch, on states of a state layout, for planning on predicted states.

A reward function takes batched torch tensors (state, action, next_state, goal) with
shapes (..., S), (..., A), (..., S), (..., G) and returns (...,). Register one for a new
env with `register(env_id, layout_name, fn)`; the planner is otherwise generic.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from motorlab.errors import MotorlabError

TorchReward = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]

_REWARDS: dict[tuple[str, str], TorchReward] = {}

TIP = slice(6, 8)  # fingertip x-y in the reacher layout


def reacher_distance(state: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    return torch.linalg.vector_norm(state[..., TIP] - goal, dim=-1)


def reacher_v5(state, action, next_state, goal):
    """Gymnasium Reacher-v5 (default weights 1, 1): distance after the step, control cost."""
    return -reacher_distance(next_state, goal) - action.square().sum(-1)


def reacher_v4(state, action, next_state, goal):
    """Gymnasium Reacher-v4 scores the distance before the step."""
    return -reacher_distance(state, goal) - action.square().sum(-1)


def register(env_id: str, layout: str, fn: TorchReward) -> None:
    """Make `fn` the planning reward of env_id under the named state layout."""
    _REWARDS[(env_id, layout)] = fn


register("Reacher-v5", "reacher", reacher_v5)
register("Reacher-v4", "reacher", reacher_v4)


def reward_for(env_id: str, layout: str) -> TorchReward:
    try:
        return _REWARDS[(env_id, layout)]
    except KeyError:
        known = ", ".join(f"{e} ({lay})" for e, lay in _REWARDS)
        raise MotorlabError(f"no torch reward for {env_id} with the {layout!r} state layout, so MPC cannot score "
                            f"plans; known: {known}. Add one with motorlab.dynamics.rewards.register().") from None
