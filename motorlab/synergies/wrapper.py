"""Act in synergy space: a Gymnasium action wrapper around a muscle- or motor-driven env.

    phi = 1:   action = z (N synergy coordinates in [-1, 1]);  env gets decode(z)
    phi < 1:   action = [z, raw] (N + M);  env gets phi * decode(z) + (1 - phi) * raw

`decode` is one affine map (the SAR's PCA, ICA and scaling inverses composed). A SAR of muscle
activations gives the env exactly that blend, as it always has: MyoSuite clips it to its action
space itself. A SAR of motor commands (ctrl or action) gives the env the blend clipped to the
env's action bounds: a robot's env need not clip (Gymnasium's Ant charges its control cost on
the action it is given, in or out of range), and decoded commands must be ones the motors can
execute. A SAR fitted on a robot's actuator
controls (`collect --signal ctrl`) drives the env's action, which is the control for
Gymnasium's MuJoCo envs; where the env's action bounds differ from the recorded bounds (an
env that takes normalized actions), decoded commands are mapped linearly from the one box
to the other first.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from motorlab.errors import MotorlabError
from motorlab.synergies.sar import SAR, load_sar, signal_of

_WHAT = {"act": "muscles", "ctrl": "actuator controls (ctrl)", "action": "action dimensions"}


class SynergyActionWrapper(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Map synergy (and, for phi < 1, raw) actions to the env's muscle or motor actions.

    Args:
        env: an env whose action space is Box(M,) with M == sar.n_muscles (the size of the
            signal the SAR decodes to: muscles, actuator controls or actions).
        sar: a fitted SAR, or a path to sar.npz.
        phi: weight of the synergy part, in (0, 1].

    Raises:
        MotorlabError: phi out of range, an action space that is not a Box, or the SAR's size
            differs from the env's actions.
    """

    def __init__(self, env: gym.Env, sar: SAR | str | Path, phi: float = 1.0):
        gym.utils.RecordConstructorArgs.__init__(self, sar=sar, phi=phi)
        super().__init__(env)
        if not 0.0 < phi <= 1.0:
            raise MotorlabError(f"phi must be in (0, 1] (1 = synergies only), got {phi}.")
        self.sar = sar if isinstance(sar, SAR) else load_sar(Path(sar))
        self.signal, rec_low, rec_high = signal_of(self.sar)
        inner = env.action_space
        name = env.spec.id if env.spec else "the env"
        if not isinstance(inner, gym.spaces.Box):
            raise MotorlabError(f"{name} has a {type(inner).__name__} action space; synergy actions need a Box.")
        if inner.shape != (self.sar.n_muscles,):
            raise MotorlabError(
                f"the SAR decodes to {self.sar.n_muscles} {_WHAT.get(self.signal, 'muscles')} but {name} "
                f"takes actions of shape {inner.shape}; fit or import a SAR for this body."
            )
        self.phi = float(phi)
        n = self.sar.n_synergies
        low, high = -np.ones(n), np.ones(n)
        if self.phi < 1.0:  # synergy coordinates, then the env's own actions
            low, high = np.concatenate([low, inner.low]), np.concatenate([high, inner.high])
        self.action_space = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        weight, bias = self._to_action_box(inner, rec_low, rec_high)
        # The blend is affine too: [z, raw] @ [[phi W], [(1 - phi) I]] + phi b, precomputed so
        # that a step is one small matmul, one add and one clip.
        m = self.sar.n_muscles
        blend = [self.phi * weight] + ([(1.0 - self.phi) * np.eye(m)] if self.phi < 1.0 else [])
        self._matrix = np.ascontiguousarray(np.vstack(blend))
        self._bias = self.phi * bias
        self._low, self._high = inner.low.astype(np.float64), inner.high.astype(np.float64)
        self._clip = self.signal != "act"  # muscle SARs: unchanged, MyoSuite bounds its actions itself
        self._dtype = inner.dtype

    def _to_action_box(self, inner: gym.spaces.Box, low: np.ndarray | None,
                       high: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The decode map in the env's action units: the SAR's own for muscles (MyoSuite takes
        activations as actions), else rescaled from the recorded box to the action box on the
        elements where both are finite and differ."""
        weight, bias = self.sar.weight, self.sar.bias
        if self.signal == "act" or low is None or high is None:
            return weight, bias
        a_low, a_high = inner.low.astype(np.float64), inner.high.astype(np.float64)
        finite = np.isfinite(low) & np.isfinite(high) & np.isfinite(a_low) & np.isfinite(a_high) & (high > low)
        if not finite.any() or (np.allclose(low[finite], a_low[finite]) and np.allclose(high[finite], a_high[finite])):
            return weight, bias  # Gymnasium's MuJoCo envs: the action box is the ctrlrange
        scale = np.where(finite, (a_high - a_low) / np.where(finite, high - low, 1.0), 1.0)
        shift = np.where(finite, a_low - low * scale, 0.0)
        return weight * scale, bias * scale + shift

    def action(self, action):
        a = np.asarray(action, dtype=np.float64)
        if a.shape != self.action_space.shape:
            raise MotorlabError(f"synergy action has shape {a.shape}, expected {self.action_space.shape}.")
        command = np.dot(a, self._matrix)
        command += self._bias
        if self._clip:
            np.clip(command, self._low, self._high, out=command)  # the env's own bounds
        return command.astype(self._dtype)
