"""TD3 (Stable-Baselines3): off-policy, continuous actions, takes --her."""

from typing import Any

from motorlab.algos.base import OffPolicy


class TD3(OffPolicy):
    """A deterministic actor: its output is the action (tanh'd in the network itself)."""

    def actor(self, network: Any, x: Any, states: tuple) -> tuple[Any, tuple]:
        return network.actor(x), states


ALGORITHM = TD3(
    name="td3",
    title="TD3",
    summary="Twin Delayed DDPG (Stable-Baselines3), off-policy; Box actions",
    cls="stable_baselines3:TD3",
    networks={"TD3Policy": "stable_baselines3.td3.policies:TD3Policy",
              "TD3MultiInputPolicy": "stable_baselines3.td3.policies:MultiInputPolicy"},
    zip_modules=("stable_baselines3.td3.policies",),
    tanh_in_actor=True,
)
