"""Act in synergy space: a Gymnasium action wrapper around a muscle-driven env.

    phi = 1:   action = z (N synergy coordinates in [-1, 1]);  env gets decode(z)
    phi < 1:   action = [z, raw] (N + M);  env gets phi * decode(z) + (1 - phi) * raw

`decode` is one affine map (the SAR's PCA, ICA and scaling inverses composed).
The env receives exactly that blend; bounding it is the env's job (MyoSuite clips).
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from motorlab.errors import MotorlabError
from motorlab.synergy.sar import SAR, load_sar


class SynergyActionWrapper(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Map synergy (and, for phi < 1, raw) actions to the env's muscle actions.

    Args:
        env: an env whose action space is Box(M,) with M == sar.n_muscles.
        sar: a fitted SAR, or a path to sar.npz.
        phi: weight of the synergy part, in (0, 1].

    Raises:
        MotorlabError: phi out of range, or the SAR's muscle count differs from the env's actions.
    """

    def __init__(self, env: gym.Env, sar: SAR | str | Path, phi: float = 1.0):
        gym.utils.RecordConstructorArgs.__init__(self, sar=sar, phi=phi)
        super().__init__(env)
        if not 0.0 < phi <= 1.0:
            raise MotorlabError(f"phi must be in (0, 1] (1 = synergies only), got {phi}.")
        self.sar = sar if isinstance(sar, SAR) else load_sar(Path(sar))
        inner = env.action_space
        if not isinstance(inner, gym.spaces.Box) or inner.shape != (self.sar.n_muscles,):
            raise MotorlabError(
                f"the SAR decodes to {self.sar.n_muscles} muscles but {env.spec.id if env.spec else 'the env'} "
                f"takes actions of shape {inner.shape}; fit or import a SAR for this body."
            )
        self.phi = float(phi)
        n = self.sar.n_synergies
        low, high = -np.ones(n), np.ones(n)
        if self.phi < 1.0:  # synergy coordinates, then the env's own actions
            low, high = np.concatenate([low, inner.low]), np.concatenate([high, inner.high])
        self.action_space = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        # The blend is affine too: [z, raw] @ [[phi W], [(1 - phi) I]] + phi b, precomputed so
        # that a step is one small matmul and one add.
        m = self.sar.n_muscles
        blend = [self.phi * self.sar.weight] + ([(1.0 - self.phi) * np.eye(m)] if self.phi < 1.0 else [])
        self._matrix = np.ascontiguousarray(np.vstack(blend))
        self._bias = self.phi * self.sar.bias
        self._dtype = inner.dtype

    def action(self, action):
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise MotorlabError(f"synergy action has shape {a.shape}, expected {self.action_space.shape}.")
        muscles = np.dot(a, self._matrix)
        muscles += self._bias
        return muscles.astype(self._dtype)
