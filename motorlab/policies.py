"""Load any policy: a run folder, or a built-in controller spec.

    runs/ppo-1/          a run folder written by `motorlab train`
    pid                  PID with default gains for the env
    pid:kp=[1,20,0,0],kd=[1,3,0,0]
    zero | random        baselines

Run folders store policies pickle-free: `policy.json` (type, architecture,
spaces) and, for neural policies, `policy.safetensors` (weights and observation
normalization). SB3's `model.zip` is kept for continuing training but never
unpickled here.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from motorlab.control.lqr import LQRPolicy
from motorlab.control.pid import make_pid
from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_bytes, read_json, require_run_dir, write_json


class Policy(Protocol):
    """What every policy does: start a batch of episodes, map observations to actions."""

    def reset(self, n: int) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...

    # Optional: `reset_row(i)` starts a new episode in row i alone (stateful controllers clear that
    # row's state); evaluation then starts each env's next episode as soon as the last one ends.


POLICY_JSON = "policy.json"
POLICY_WEIGHTS = "policy.safetensors"


class ZeroPolicy:
    def __init__(self, action_space: gym.spaces.Box):
        self.action = np.clip(np.zeros(action_space.shape), action_space.low, action_space.high).astype(np.float32)

    def reset(self, n: int) -> None:
        pass

    def reset_row(self, i: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.repeat(self.action[None], len(obs), axis=0)


class RandomPolicy:
    def __init__(self, action_space: gym.spaces.Box, seed: int = 0):
        self.low, self.high = action_space.low, action_space.high
        self.rng = np.random.default_rng(seed)

    def reset(self, n: int) -> None:
        pass

    def reset_row(self, i: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.rng.uniform(self.low, self.high, size=(len(obs), *self.low.shape)).astype(np.float32)


# ---- SB3 policies, pickle-free -------------------------------------------------

def policy_classes() -> dict[str, type]:
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.sac.policies import SACPolicy
    from stable_baselines3.td3.policies import TD3Policy

    return {"ActorCriticPolicy": ActorCriticPolicy, "SACPolicy": SACPolicy, "TD3Policy": TD3Policy}


def encode_classes(value: Any) -> Any:
    if isinstance(value, type):
        return {"class": f"{value.__module__}.{value.__qualname__}"}
    if isinstance(value, dict):
        return {k: encode_classes(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode_classes(v) for v in value]
    return value


def decode_classes(value: Any) -> Any:
    if isinstance(value, dict) and set(value) == {"class"}:
        module, _, name = value["class"].rpartition(".")
        if not module.startswith(("torch.nn", "torch.optim")):
            raise MotorlabError(f"policy.json names class {value['class']!r}; only torch.nn / torch.optim classes are allowed.")
        return getattr(importlib.import_module(module), name)
    if isinstance(value, dict):
        return {k: decode_classes(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode_classes(v) for v in value]
    return value


def _box(space: gym.spaces.Box) -> dict:
    # Bounds as strings so that +-inf survive JSON ("inf" is not JSON).
    return {"shape": list(space.shape), "dtype": str(space.dtype),
            "low": [repr(float(v)) for v in space.low.ravel()], "high": [repr(float(v)) for v in space.high.ravel()]}


def _unbox(d: dict) -> gym.spaces.Box:
    shape, dtype = tuple(d["shape"]), np.dtype(d["dtype"])
    low = np.array([float(v) for v in d["low"]], dtype=dtype).reshape(shape)
    high = np.array([float(v) for v in d["high"]], dtype=dtype).reshape(shape)
    return gym.spaces.Box(low=low, high=high, dtype=dtype)


class SB3Policy:
    """An SB3 policy network with optional observation normalization; deterministic actions."""

    def __init__(self, policy, obs_mean=None, obs_var=None, clip_obs: float = 10.0, epsilon: float = 1e-8,
                 deterministic: bool = True):
        self.policy = policy
        self.deterministic = deterministic  # False: sample from the policy (uses torch's RNG)
        self.policy.set_training_mode(False)
        self.obs_mean, self.obs_var = obs_mean, obs_var
        self.clip_obs, self.epsilon = clip_obs, epsilon

    def reset(self, n: int) -> None:
        pass

    def reset_row(self, i: int) -> None:
        pass  # stateless: history, when there is one, lives in the env's observation

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        expected = self.policy.observation_space.shape
        if obs.shape[1:] != expected:
            raise MotorlabError(
                f"this policy expects observations of shape {expected} but the env gives {obs.shape[1:]}; "
                "evaluate it with the env settings it was trained with (--history, --delay)."
            )
        if self.obs_mean is not None:
            obs = np.clip((obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon), -self.clip_obs, self.clip_obs)
            obs = obs.astype(np.float32)
        action, _ = self.policy.predict(obs, deterministic=self.deterministic)
        return action


def save_sb3_policy(run_dir: Path, model, algo: str, vecnorm=None) -> None:
    """Write policy.safetensors + policy.json for an SB3 model (no pickle)."""
    from safetensors.numpy import save

    tensors = {f"policy.{k}": v.detach().cpu().numpy() for k, v in model.policy.state_dict().items()}
    meta: dict[str, Any] = {
        "type": "sb3",
        "algo": algo,
        "policy_class": type(model.policy).__name__,
        "policy_kwargs": encode_classes(dict(model.policy_kwargs)),
        "use_sde": bool(getattr(model, "use_sde", False)) if algo == "ppo" else None,
        "observation_space": _box(model.observation_space),
        "action_space": _box(model.action_space),
        "obs_norm": None,
    }
    if vecnorm is not None and vecnorm.norm_obs:
        tensors["obs_rms.mean"] = vecnorm.obs_rms.mean.astype(np.float64)
        tensors["obs_rms.var"] = vecnorm.obs_rms.var.astype(np.float64)
        meta["obs_norm"] = {"clip_obs": float(vecnorm.clip_obs), "epsilon": float(vecnorm.epsilon)}
    atomic_write_bytes(Path(run_dir) / POLICY_WEIGHTS, save({k: np.ascontiguousarray(v) for k, v in tensors.items()}))
    write_json(Path(run_dir) / POLICY_JSON, meta)


class _NoOptimizer:
    """What a loaded policy gets in place of the optimizer SB3 builds beside its networks: it acts and
    never learns, and building a torch optimizer imports torch._dynamo, over a second of the start-up
    of every command that loads a policy (evaluate, video, zeroshot, synergies collect and their workers)."""

    def __init__(self, params: Any, **settings: Any):
        pass


def _load_sb3(run_dir: Path, meta: dict) -> SB3Policy:
    import torch
    from safetensors import SafetensorError
    from safetensors.numpy import load_file

    classes = policy_classes()
    cls = classes.get(meta.get("policy_class", ""))
    if cls is None:
        raise MotorlabError(f"{run_dir / POLICY_JSON}: unknown policy class {meta.get('policy_class')!r}.")
    kwargs = decode_classes(meta.get("policy_kwargs") or {})
    kwargs["optimizer_class"] = _NoOptimizer  # the networks only (the run's optimizer class is still checked above)
    if meta.get("use_sde") is not None:
        kwargs["use_sde"] = meta["use_sde"]
    try:
        policy = cls(_unbox(meta["observation_space"]), _unbox(meta["action_space"]), lambda _: 0.0, **kwargs)
    except (RuntimeError, MemoryError, TypeError, ValueError, KeyError, AssertionError) as e:
        # a damaged policy.json (a negative or absurd layer width, a wrong keyword) fails in torch or SB3
        raise MotorlabError(f"{run_dir / POLICY_JSON} does not describe a network SB3 can build "
                            f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}); re-run training.") from None
    path = Path(run_dir) / POLICY_WEIGHTS
    try:
        tensors = load_file(str(path))
    except (SafetensorError, OSError, ValueError) as e:
        raise MotorlabError(f"{path} is missing or corrupt ({e}); re-run training to write it again.") from None
    state = {k[len("policy."):]: torch.from_numpy(v.copy()) for k, v in tensors.items() if k.startswith("policy.")}
    try:
        policy.load_state_dict(state)
    except RuntimeError as e:
        raise MotorlabError(f"{path} does not match {POLICY_JSON} ({str(e).splitlines()[0]}); re-run training.") from None
    norm = meta.get("obs_norm")
    if norm:
        return SB3Policy(policy, tensors["obs_rms.mean"], tensors["obs_rms.var"], norm["clip_obs"], norm["epsilon"])
    return SB3Policy(policy)


# ---- saving / loading -------------------------------------------------------

def save_controller(run_dir: Path, controller) -> None:
    """Write policy.json for a PID or LQR controller (all numbers inline)."""
    write_json(Path(run_dir) / POLICY_JSON, controller.to_dict())


def load_run_policy(run_dir: Path) -> Policy:
    """The policy saved in a finished run folder, pickle-free."""
    return load_policy_files(require_run_dir(Path(run_dir)))


def load_policy_files(run_dir: Path) -> Policy:
    """The policy in `run_dir` (policy.json, policy.safetensors), finished run or not."""
    run_dir = Path(run_dir)
    meta = read_json(run_dir / POLICY_JSON)
    kind = meta.get("type")
    try:
        if kind == "sb3":
            return _load_sb3(run_dir, meta)
        if kind == "lqr":
            return LQRPolicy.from_dict(meta)
        if kind == "pid":
            from motorlab.control.pid import PIDController

            return PIDController(meta["kp"], meta["ki"], meta["kd"], dt=meta["dt"],
                                 low=np.asarray(meta["low"]), high=np.asarray(meta["high"]))
    except (KeyError, TypeError, ValueError) as e:
        raise MotorlabError(f"{run_dir / POLICY_JSON} is incomplete or corrupt ({e!r}); re-run training.") from None
    raise MotorlabError(f"{run_dir / POLICY_JSON} has unknown policy type {kind!r}.")


def load_policy(spec: str, env: gym.Env, env_id: str, seed: int = 0) -> Policy:
    """A policy from a run folder or a built-in spec (see module doc), for `env`.

    Raises:
        MotorlabError: unknown spec, missing or corrupt run folder.
    """
    head = spec.split(":", 1)[0]
    if head == "pid":
        return make_pid(spec, env_id, int(np.prod(env.observation_space.shape)), float(env.unwrapped.dt),
                        env.action_space.low, env.action_space.high)
    if spec == "zero":
        return ZeroPolicy(env.action_space)
    if spec == "random":
        return RandomPolicy(env.action_space, seed)
    path = Path(spec)
    if not path.exists():
        raise MotorlabError(unknown_policy_message(spec))
    return load_run_policy(path)


BUILTIN_POLICIES = ("pid", "zero", "random")


def unknown_policy_message(spec: str) -> str:
    return (f"policy {spec!r} is neither a run folder nor a built-in controller; "
            "give a run folder from `motorlab train`, or pid, pid:kp=[...],kd=[...], zero, random.")
