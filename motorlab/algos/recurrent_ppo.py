"""Recurrent PPO (sb3-contrib, `--algo recurrentppo`): PPO with an LSTM between the features and
the actor's (and critic's) layers, for tasks whose state the observation does not show whole
(delays, latency, hidden parameters), in place of a stacked history.

The policy keeps an LSTM state per env row: `reset(n)` starts n rows from zeros and `reset_row(i)`
zeros row i when its next episode starts (motorlab.policies.SB3Policy asks this module for both).
In ONNX the state is an explicit input/output pair (`lstm_h`, `lstm_c` in; `next_lstm_h`,
`next_lstm_c` out, each [layers, batch, hidden]): zeros at an episode's start, then each step's
outputs fed back as the next step's inputs; policy.onnx.json describes them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from motorlab.algos.base import ANY_ACTIONS, OnPolicy, StateSpec

STATE_NAMES = ("lstm_h", "lstm_c")  # the actor LSTM's hidden and cell states


class RecurrentPPO(OnPolicy):
    """PPO with an LSTM: stateful acting, a state pair in the deployed graph."""

    def initial_state(self, network: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
        layers, _, hidden = network.lstm_hidden_state_shape
        return np.zeros((layers, n, hidden), np.float32), np.zeros((layers, n, hidden), np.float32)

    def reset_row(self, state: Any, i: int) -> Any:
        if state is None:
            return state
        h, c = (s.copy() for s in state)
        h[:, i], c[:, i] = 0.0, 0.0
        return h, c

    def predict(self, network: Any, obs: Any, state: Any, deterministic: bool) -> tuple[np.ndarray, Any]:
        n = len(next(iter(obs.values()))) if isinstance(obs, dict) else len(obs)
        if state is None or state[0].shape[1] != n:  # a batch of another size: new episodes
            state = self.initial_state(network, n)
        # episode starts are zeroed rows (reset_row), not SB3's flags
        action, state = network.predict(obs, state=state, episode_start=np.zeros(n, dtype=bool),
                                        deterministic=deterministic)
        return action, state

    def onnx_states(self, network: Any) -> tuple[StateSpec, ...]:
        layers, _, hidden = network.lstm_hidden_state_shape
        what = {"lstm_h": "hidden", "lstm_c": "cell"}
        return tuple(StateSpec(name, (layers, "batch", hidden),
                               f"the actor LSTM's {what[name]} state: zeros at an episode's start, else the previous "
                               f"step's next_{name}") for name in STATE_NAMES)

    def actor(self, network: Any, x: Any, states: tuple) -> tuple[Any, tuple]:
        features = network.pi_features_extractor(x)
        # one step of the sequence SB3's _process_sequence runs, the rows' resets done by the caller
        latent, (h, c) = network.lstm_actor(features.unsqueeze(0), tuple(states))
        latent = network.mlp_extractor.forward_actor(latent.squeeze(0))
        return network.action_net(latent), (h, c)


ALGORITHM = RecurrentPPO(
    name="recurrentppo",
    title="RecurrentPPO",
    summary="PPO with an LSTM policy (sb3-contrib), on-policy, for partly observed tasks; Box, Discrete, "
            "MultiDiscrete or MultiBinary actions",
    cls="sb3_contrib:RecurrentPPO",
    mlp_policy="MlpLstmPolicy",
    multi_input_policy="MultiInputLstmPolicy",
    actions=ANY_ACTIONS,
    networks={"RecurrentActorCriticPolicy": "sb3_contrib.common.recurrent.policies:RecurrentActorCriticPolicy",
              "RecurrentMultiInputActorCriticPolicy":
                  "sb3_contrib.common.recurrent.policies:RecurrentMultiInputActorCriticPolicy"},
    zip_modules=("sb3_contrib.common.recurrent.policies", "sb3_contrib.ppo_recurrent.policies"),
)
