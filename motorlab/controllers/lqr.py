"""Model-based control for regulation tasks: identify a linear model from data,
control it with an infinite-horizon LQR, refit as data arrives.

The model is an ARX model on what the controller knows: its last `obs_lags`
observations and its last `act_lags` commanded actions,

    o_{t+1} = sum_i A_i o_{t-i} + sum_j B_j u_{t-j},

fitted by (ridge) least squares and put in companion (state-space) form, so that
unobserved state such as an actuation filter is recovered from the action memory.
This is motorlab's most sample-efficient learner for near-linear balance tasks
(InvertedPendulum in ~100-200 steps, with or without a 0.2 s delay): scipy's DARE solver does the control design.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from motorlab.envs import EnvConfig, make_env
from motorlab.envs.spaces import require_actions
from motorlab.errors import MotorlabError


class LQRSettings(BaseModel):
    """Settings of the linear-model + LQR learner (recipe table `[lqr]`)."""

    model_config = ConfigDict(extra="forbid")

    # Two observations recover the true state behind a low-pass perception filter.
    obs_lags: int = Field(2, ge=1, description="past observations in the model state")
    act_lags: int = Field(1, ge=0, description="past commanded actions in the model state")
    state_cost: float = Field(1.0, gt=0, description="LQR weight on the current observation")
    action_cost: float = Field(0.1, gt=0, description="LQR weight on the action")
    batch_steps: int = Field(100, ge=10, description="env steps collected between refits")
    random_std: float = Field(0.33, ge=0, description="action noise before the first model, fraction of the half-range")
    explore_std: float = Field(0.1, ge=0, description="action noise once a model exists, fraction of the half-range")
    ridge: float = Field(1e-6, ge=0, description="ridge regularization of the least-squares fit")


@dataclass
class LQRPolicy:
    """Linear state feedback u = -K z on the controller's memory z, batched."""

    K: np.ndarray
    obs_dim: int
    act_dim: int
    obs_lags: int
    act_lags: int
    low: np.ndarray
    high: np.ndarray
    noise_std: float = 0.0
    rng: np.random.Generator | None = None

    def reset(self, n: int) -> None:
        self._obs_hist = np.zeros((n, self.obs_lags, self.obs_dim))
        self._act_hist = np.zeros((n, self.act_lags, self.act_dim))
        self._started = False
        self.last_z = None

    def reset_row(self, i: int) -> None:
        """Start a new episode in row i only (used while collecting data)."""
        self._act_hist[i] = 0.0
        self._obs_hist[i] = np.nan  # filled with the first observation on the next act()

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        if obs.shape[1] != self.obs_dim:
            raise MotorlabError(
                f"this LQR policy was fitted on {self.obs_dim} observation elements but the env gives {obs.shape[1]}; "
                "evaluate it with the env settings it was trained with (delay, history)."
            )
        if not getattr(self, "_started", False) or self._obs_hist.shape[0] != obs.shape[0]:
            self.reset(obs.shape[0])
            self._obs_hist[:] = obs[:, None]
            self._started = True
        else:
            fresh = np.isnan(self._obs_hist[:, 0, 0])
            self._obs_hist = np.roll(self._obs_hist, 1, axis=1)
            self._obs_hist[:, 0] = obs
            self._obs_hist[fresh] = obs[fresh, None]
        z = np.concatenate([self._obs_hist.reshape(len(obs), -1), self._act_hist.reshape(len(obs), -1)], axis=1)
        u = -z @ self.K.T
        if self.noise_std > 0:
            half = (self.high - self.low) / 2
            u = u + self.noise_std * half * (self.rng or np.random.default_rng()).normal(size=u.shape)
        u = np.clip(u, self.low, self.high)
        if self.act_lags:
            self._act_hist = np.roll(self._act_hist, 1, axis=1)
            self._act_hist[:, 0] = u
        self.last_z = z
        return u.astype(np.float32)

    def to_dict(self) -> dict:
        return {"type": "lqr", "K": self.K.tolist(), "obs_dim": self.obs_dim, "act_dim": self.act_dim,
                "obs_lags": self.obs_lags, "act_lags": self.act_lags,
                "low": np.asarray(self.low).tolist(), "high": np.asarray(self.high).tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "LQRPolicy":
        return cls(K=np.asarray(d["K"], dtype=np.float64), obs_dim=int(d["obs_dim"]), act_dim=int(d["act_dim"]),
                   obs_lags=int(d["obs_lags"]), act_lags=int(d["act_lags"]),
                   low=np.asarray(d["low"]), high=np.asarray(d["high"]))


def require_bounded(space, user: str, env_id: str) -> None:
    """Refuse a Box of actions without finite bounds: exploration noise and clipping are scaled by them."""
    if not (np.isfinite(space.low).all() and np.isfinite(space.high).all()):
        raise MotorlabError(f"{user} scales its exploration by the action bounds, and {env_id}'s are unbounded "
                            f"({space}); give your env finite action bounds (its action_space's low and high).")


def fit_linear_model(Z: np.ndarray, U: np.ndarray, O_next: np.ndarray, ridge: float = 1e-6):
    """Least-squares ARX fit. Returns (A_top, B_top, mse): O_next ~ Z A_top^T + U B_top^T."""
    X = np.hstack([Z, U])
    W = np.linalg.solve(X.T @ X + ridge * np.eye(X.shape[1]), X.T @ O_next)
    mse = float(np.mean((X @ W - O_next) ** 2))
    nz = Z.shape[1]
    return W[:nz].T, W[nz:].T, mse


def companion_form(A_top: np.ndarray, B_top: np.ndarray, obs_lags: int, act_lags: int):
    """State-space (A, B) for z = [o_t..o_{t-P+1}, u_{t-1}..u_{t-Q}]."""
    d, nz = A_top.shape
    m = B_top.shape[1]
    A = np.zeros((nz, nz))
    B = np.zeros((nz, m))
    A[:d] = A_top
    B[:d] = B_top
    for k in range(1, obs_lags):  # shift observations back one slot
        A[d * k : d * (k + 1), d * (k - 1) : d * k] = np.eye(d)
    a0 = d * obs_lags
    if act_lags:
        B[a0 : a0 + m] = np.eye(m)  # u_t becomes the newest remembered action
        for k in range(1, act_lags):
            A[a0 + m * k : a0 + m * (k + 1), a0 + m * (k - 1) : a0 + m * k] = np.eye(m)
    return A, B


def lqr_gain(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Infinite-horizon discrete LQR gain K (u = -K z), from scipy's DARE solver."""
    import scipy.linalg  # heavy: loaded when a controller is designed, not when settings are read

    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    return np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def learn_lqr(
    env_cfg: EnvConfig,
    settings: LQRSettings,
    timesteps: int,
    seed: int,
    on_update: Callable[[int, LQRPolicy, dict], bool],
    on_episode: Callable[[int, float, int], None] | None = None,
    on_steps: Callable[[int], None] | None = None,
) -> tuple[LQRPolicy | None, int]:
    """Collect data, refit the model and the LQR gain every `batch_steps` steps.

    Args:
        on_update: called after each refit with (env steps so far, policy, fit info);
            returning True stops learning (e.g. solved).
        on_episode: called with (env steps, episode return, length) per finished episode.
        on_steps: called with the env steps so far after each batch (for a progress bar).

    Returns:
        (final policy or None if no model could be fitted, env steps used)
    """
    rng = np.random.default_rng(seed)
    env = make_env(env_cfg)
    try:  # a linear model of continuous commands, and actions clipped to finite bounds
        require_actions(env.action_space, "the LQR learner (--algo lqr)", env_id=env_cfg.id,
                        instead="use --algo ppo")
        require_bounded(env.action_space, "the LQR learner (--algo lqr)", env_cfg.id)
    except MotorlabError:
        env.close()
        raise
    space = env.action_space
    obs_dim = int(np.prod(env.observation_space.shape))
    act_dim = int(np.prod(space.shape))
    nz = obs_dim * settings.obs_lags + act_dim * settings.act_lags
    policy = LQRPolicy(K=np.zeros((act_dim, nz)), obs_dim=obs_dim, act_dim=act_dim,
                       obs_lags=settings.obs_lags, act_lags=settings.act_lags,
                       low=space.low.astype(np.float64), high=space.high.astype(np.float64),
                       noise_std=settings.random_std, rng=rng)
    Q = np.zeros((nz, nz))
    Q[:obs_dim, :obs_dim] = settings.state_cost * np.eye(obs_dim)
    R = settings.action_cost * np.eye(act_dim)
    Zs, Us, Os = [], [], []
    fitted = False
    steps, ep_return, ep_len = 0, 0.0, 0
    obs, _ = env.reset(seed=seed)
    policy.reset(1)
    while steps < timesteps:
        batch_end = min(steps + settings.batch_steps, timesteps)
        while steps < batch_end:
            u = policy.act(obs[None])[0]
            Zs.append(policy.last_z[0].copy())
            Us.append(u.astype(np.float64))
            obs, reward, terminated, truncated, _ = env.step(u)
            Os.append(np.asarray(obs, dtype=np.float64).reshape(-1))
            steps += 1
            ep_return += float(reward)
            ep_len += 1
            if terminated or truncated:
                if on_episode:
                    on_episode(steps, ep_return, ep_len)
                obs, _ = env.reset()
                policy.reset_row(0)
                ep_return, ep_len = 0.0, 0
        if on_steps:
            on_steps(steps)
        # Transitions whose state spans an episode start are fine: the memory is
        # re-filled with the first observation, exactly as at evaluation time.
        A_top, B_top, mse = fit_linear_model(np.array(Zs), np.array(Us), np.array(Os), settings.ridge)
        A, B = companion_form(A_top, B_top, settings.obs_lags, settings.act_lags)
        try:
            policy.K = lqr_gain(A, B, Q, R)
            fitted = True
        except (np.linalg.LinAlgError, ValueError):
            continue  # model not stabilizable yet: collect more data
        policy.noise_std = settings.explore_std
        greedy = LQRPolicy.from_dict(policy.to_dict())
        if on_update(steps, greedy, {"model_mse": mse, "transitions": len(Zs)}):
            break
    env.close()
    if not fitted:
        return None, steps
    return LQRPolicy.from_dict(policy.to_dict()), steps
