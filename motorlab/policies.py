"""Load any policy: a run folder, or a built-in controller spec.

    runs/ppo-1/          a run folder written by `motorlab train`
    pid                  PID with default gains for the env
    pid:kp=[1,20,0,0],kd=[1,3,0,0]
    zero | random        baselines

Run folders store policies pickle-free: `policy.json` (type, architecture,
spaces) and, for neural policies, `policy.safetensors` (weights and observation
normalization). SB3's `model.zip` is kept for continuing training but never
unpickled here.

Spaces beyond one Box (motorlab.envs.spaces): a policy trained on a Dict observation
(MultiInputPolicy) records its `obs_layout` and is given FLAT observations, as every evaluation
env gives them (a Dict flattened key by key); it turns them back into the Dict its network was
trained on. Its observation normalization is stored per key (`obs_rms.<key>.mean`, `.var`).
Discrete actions come out as action indices (int64).
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from motorlab.controllers.lqr import LQRPolicy
from motorlab.controllers.pid import pid_for_env
from motorlab.envs.spaces import (
    KeySlice,
    decode_space,
    encode_space,
    flat_space,
    is_dict,
    layout_json,
    obs_layout,
    require_actions,
    unflatten_batch,
)
from motorlab.errors import MotorlabError
from motorlab.runs import POLICY_JSON, atomic_write_bytes, read_json, require_run_dir, write_json


class Policy(Protocol):
    """What every policy does: start a batch of episodes, map observations to actions."""

    def reset(self, n: int) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...

    # Optional: `reset_row(i)` starts a new episode in row i alone (stateful controllers clear that
    # row's state); evaluation then starts each env's next episode as soon as the last one ends.


POLICY_WEIGHTS = "policy.safetensors"


class ZeroPolicy:
    """The zero command (clipped into the action box) at every step: the "do nothing" baseline.

    Raises:
        MotorlabError: actions that are not a Box (an action index has no "zero").
    """

    def __init__(self, action_space: gym.Space, env_id: str | None = None):
        require_actions(action_space, "the zero policy", instead="use the random policy", env_id=env_id)
        self.action = np.clip(np.zeros(action_space.shape), action_space.low, action_space.high).astype(np.float32)

    def reset(self, n: int) -> None:
        pass

    def reset_row(self, i: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.repeat(self.action[None], len(obs), axis=0)


class RandomPolicy:
    """Uniform random actions: in the action box, or among a Discrete space's actions.

    Raises:
        MotorlabError: an action space that is neither.
    """

    def __init__(self, action_space: gym.Space, seed: int = 0, env_id: str | None = None):
        self.discrete = isinstance(action_space, gym.spaces.Discrete)
        if self.discrete:
            self.start, self.n = int(action_space.start), int(action_space.n)
        else:
            require_actions(action_space, "the random policy", "Box or Discrete actions", env_id=env_id)
            if not (np.isfinite(action_space.low).all() and np.isfinite(action_space.high).all()):
                raise MotorlabError(f"the random policy draws actions between the action bounds, and "
                                    f"{env_id or 'this env'}'s are unbounded ({action_space}); give your env finite "
                                    "action bounds, or evaluate the zero policy or a trained one.")
            self.low, self.high = action_space.low, action_space.high
        self.rng = np.random.default_rng(seed)

    def reset(self, n: int) -> None:
        pass

    def reset_row(self, i: int) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:
        if self.discrete:
            return self.rng.integers(self.start, self.start + self.n, size=len(obs), dtype=np.int64)
        return self.rng.uniform(self.low, self.high, size=(len(obs), *self.low.shape)).astype(np.float32)


# ---- SB3 policies, pickle-free -------------------------------------------------

def policy_classes() -> dict[str, type]:
    """The SB3 policy classes a policy.json may name, by the name it writes (`policy_class_name`):
    every SB3 algorithm's in motorlab/algos/ (imports SB3)."""
    from motorlab import algos

    return {name: cls for algo in algos.registry().values() if algo.sb3
            for name, cls in algo.network_classes().items()}


def policy_class_name(policy: Any) -> str | None:
    """The name policy.json gives the class of an SB3 policy network (None: not one motorlab saves)."""
    return next((name for name, cls in policy_classes().items() if type(policy) is cls), None)


def encode_classes(value: Any) -> Any:
    if isinstance(value, type):
        return {"class": f"{value.__module__}.{value.__qualname__}"}
    if isinstance(value, dict):
        return {k: encode_classes(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode_classes(v) for v in value]
    return value


def decode_classes(value: Any) -> Any:
    """The torch classes `encode_classes` wrote, imported again: only torch.nn / torch.optim ones.

    Raises:
        MotorlabError: any other name, or one torch does not have (a tampered policy.json).
    """
    if isinstance(value, dict) and set(value) == {"class"}:
        path = value["class"]
        module, _, name = path.rpartition(".") if isinstance(path, str) else ("", "", "")
        if not module.startswith(("torch.nn", "torch.optim")) or module.split(".")[1] not in ("nn", "optim"):
            raise MotorlabError(f"policy.json names class {path!r}; only torch.nn / torch.optim classes are allowed.")
        try:
            cls = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            cls = None
        if not isinstance(cls, type):
            raise MotorlabError(f"policy.json names class {path!r}, which torch does not have.")
        return cls
    if isinstance(value, dict):
        return {k: decode_classes(v) for k, v in value.items()}
    if isinstance(value, list):
        return [decode_classes(v) for v in value]
    return value


class SB3Policy:
    """An SB3 policy network with optional observation normalization; deterministic actions.

    Its algorithm (motorlab.algos; by default the one whose network class it is) says how it
    acts: most act on each observation alone; a recurrent one keeps a state per row, which
    `reset(n)` starts from zeros and `reset_row(i)` zeroes for row i's next episode.

    It acts on flat observation batches, as evaluation envs give them: a network trained on a Dict
    observation (MultiInputPolicy) gets them back as that Dict (`obs_layout`). Normalization
    statistics (`obs_mean`, `obs_var`) are flat too, each key's in its slice, so that normalizing
    the flat vector normalizes every key with its own statistics.
    """

    def __init__(self, policy, obs_mean=None, obs_var=None, clip_obs: float = 10.0, epsilon: float = 1e-8,
                 deterministic: bool = True, algorithm=None):
        from motorlab import algos

        self.policy = policy
        self.algorithm = algorithm or algos.of_network(policy)
        if self.algorithm is None:
            raise MotorlabError(f"the policy is a {type(policy).__name__}, which no algorithm in motorlab/algos/ "
                                "builds.")
        self.state = None  # a recurrent policy's, row by row
        self.deterministic = deterministic  # False: sample from the policy (uses torch's RNG)
        self.policy.set_training_mode(False)
        self.obs_mean, self.obs_var = obs_mean, obs_var
        self.clip_obs, self.epsilon = clip_obs, epsilon
        self.layout: list[KeySlice] = obs_layout(policy.observation_space)  # empty: a Box observation
        self.observation_space = flat_space(policy.observation_space)  # what act() takes

    def reset(self, n: int) -> None:
        self.state = self.algorithm.initial_state(self.policy, n)

    def reset_row(self, i: int) -> None:
        # stateless (most): history, when there is one, lives in the env's observation
        self.state = self.algorithm.reset_row(self.state, i)

    def act(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        expected = self.observation_space.shape
        if obs.shape[1:] != expected:
            raise MotorlabError(
                f"this policy expects observations of shape {expected} but the env gives {obs.shape[1:]}; "
                "evaluate it with the env settings it was trained with (--history, --delay)."
            )
        if self.obs_mean is not None:
            obs = np.clip((obs - self.obs_mean) / np.sqrt(self.obs_var + self.epsilon), -self.clip_obs, self.clip_obs)
            obs = obs.astype(np.float32)
        action, self.state = self.algorithm.predict(self.policy, unflatten_batch(obs, self.layout) if self.layout
                                                    else obs, self.state, self.deterministic)
        return action


def normalization(vecnorm, observation_space: gym.Space) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
    """VecNormalize's observation statistics as {key: (mean, var)} ("" for a Box observation), in
    the order of the observation's flat layout; None when it does not normalize observations.

    Raises:
        MotorlabError: statistics of some keys of a Dict observation only.
    """
    if vecnorm is None or not vecnorm.norm_obs:
        return None
    if not is_dict(observation_space):
        return {"": (np.asarray(vecnorm.obs_rms.mean), np.asarray(vecnorm.obs_rms.var))}
    keys = [s.key for s in obs_layout(observation_space)]
    if set(vecnorm.norm_obs_keys or []) != set(keys):
        raise MotorlabError(f"VecNormalize normalizes the observation keys {vecnorm.norm_obs_keys}, not all of "
                            f"{keys}; motorlab saves statistics of every key.")
    return {k: (np.asarray(vecnorm.obs_rms[k].mean), np.asarray(vecnorm.obs_rms[k].var)) for k in keys}


def flat_statistics(stats: dict[str, tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Per-key statistics as one flat mean and variance, each key's in its slice of the flat observation."""
    return (np.concatenate([m.ravel() for m, _ in stats.values()]).astype(np.float64),
            np.concatenate([v.ravel() for _, v in stats.values()]).astype(np.float64))


def save_sb3_policy(run_dir: Path, model, algo: str, vecnorm=None) -> None:
    """Write policy.safetensors + policy.json for an SB3 model (no pickle): the network's state dict
    (weights, and buffers such as CrossQ's batch-renormalization statistics) and what builds it.

    Raises:
        MotorlabError: a policy class or space motorlab cannot save.
    """
    from safetensors.numpy import save

    from motorlab import algos

    name = policy_class_name(model.policy)
    if name is None:
        raise MotorlabError(f"the policy is a {type(model.policy).__name__}; motorlab saves "
                            f"{', '.join(policy_classes())}.")
    tensors = {f"policy.{k}": v.detach().cpu().numpy() for k, v in model.policy.state_dict().items()}
    meta: dict[str, Any] = {
        "type": "sb3",
        "algo": algo,
        "policy_class": name,
        "policy_kwargs": encode_classes(dict(model.policy_kwargs)),
        "use_sde": algos.get(algo).use_sde(model),  # on-policy classes build it beside policy_kwargs
        "observation_space": encode_space(model.observation_space),
        "action_space": encode_space(model.action_space),
        "obs_layout": layout_json(model.observation_space),  # the flat observation it acts on, key by key
        "obs_norm": None,
    }
    stats = normalization(vecnorm, model.observation_space)
    if stats is not None:
        for key, (mean, var) in stats.items():
            prefix = f"obs_rms.{key}." if key else "obs_rms."  # "obs_rms.mean", or per key "obs_rms.<key>.mean"
            tensors[prefix + "mean"] = mean.astype(np.float64)
            tensors[prefix + "var"] = var.astype(np.float64)
        meta["obs_norm"] = {"clip_obs": float(vecnorm.clip_obs), "epsilon": float(vecnorm.epsilon),
                            "keys": [k for k in stats if k] or None}
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
    cls = classes.get(meta["policy_class"])
    if cls is None:
        raise MotorlabError(f"{run_dir / POLICY_JSON}: key 'policy_class' names an unknown policy class "
                            f"{meta['policy_class']!r} (motorlab saves {', '.join(classes)}); re-run training.")
    try:
        kwargs = decode_classes(meta.get("policy_kwargs") or {})
    except MotorlabError as e:
        raise MotorlabError(f"{run_dir / POLICY_JSON}: key 'policy_kwargs': {e}") from None
    if not isinstance(kwargs, dict):
        raise _bad_key(run_dir, "policy_kwargs", kwargs, "an object")
    kwargs["optimizer_class"] = _NoOptimizer  # the networks only (the run's optimizer class is still checked above)
    if meta.get("use_sde") is not None:
        kwargs["use_sde"] = meta["use_sde"]
    spaces = tuple(_space(run_dir, meta, key) for key in ("observation_space", "action_space"))
    try:
        policy = cls(*spaces, lambda _: 0.0, **kwargs)
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
        keys = [s.key for s in obs_layout(policy.observation_space)]
        try:
            stats = {k: (tensors[f"obs_rms.{k}.mean"], tensors[f"obs_rms.{k}.var"]) for k in keys} if keys else \
                {"": (tensors["obs_rms.mean"], tensors["obs_rms.var"])}
        except KeyError as e:
            raise MotorlabError(f"{path} lacks the normalization statistics {e} that {POLICY_JSON} announces; "
                                "re-run training.") from None
        mean, var = flat_statistics(stats)
        return SB3Policy(policy, mean, var, norm["clip_obs"], norm["epsilon"])
    return SB3Policy(policy)  # its algorithm: the one whose network class it is


# ---- saving / loading -------------------------------------------------------

def load_run_policy(run_dir: Path) -> Policy:
    """The policy saved in a finished run folder, pickle-free."""
    return load_policy_files(require_run_dir(Path(run_dir)))


def load_policy_files(run_dir: Path) -> Policy:
    """The policy in `run_dir` (policy.json, policy.safetensors), finished run or not."""
    run_dir = Path(run_dir)
    meta = read_json(run_dir / POLICY_JSON)
    if not isinstance(meta, dict):
        raise MotorlabError(f"{run_dir / POLICY_JSON} holds a JSON {type(meta).__name__}, not a policy (an object "
                            "with its type and settings); re-run training.")
    kind = meta.get("type")
    check_keys(run_dir, meta, POLICY_KEYS.get(kind, {}) if isinstance(kind, str) else {})
    try:
        if kind == "sb3":
            return _load_sb3(run_dir, meta)
        if kind == "lqr":
            return LQRPolicy.from_dict(meta)
        if kind == "pid":
            from motorlab.controllers.pid import PIDController

            return PIDController(meta["kp"], meta["ki"], meta["kd"], dt=meta["dt"],
                                 low=np.asarray(meta["low"]), high=np.asarray(meta["high"]))
    except KeyError as e:
        raise MotorlabError(f"{run_dir / POLICY_JSON}: key {e.args[0]!r} is missing; re-run training.") from None
    except (TypeError, ValueError, AttributeError, IndexError, OverflowError) as e:
        raise MotorlabError(f"{run_dir / POLICY_JSON} is incomplete or corrupt ({type(e).__name__}: "
                            f"{' '.join(str(e).split())}); re-run training.") from None
    raise MotorlabError(f"{run_dir / POLICY_JSON}: key 'type' is {kind!r}, not a policy type motorlab saves "
                        f"({', '.join(POLICY_KEYS)}); re-run training.")


# What each policy type's policy.json must hold, key by key (checked before anything is built from it,
# so a tampered or damaged file is one line naming the key): "str", "int", "number", "numbers" (an
# array of finite numbers), "object".
POLICY_KEYS: dict[str, dict[str, str]] = {
    "sb3": {"policy_class": "str", "observation_space": "object", "action_space": "object"},
    "lqr": {"K": "numbers", "obs_dim": "int", "act_dim": "int", "obs_lags": "int", "act_lags": "int",
            "low": "numbers", "high": "numbers"},
    "pid": {"kp": "numbers", "ki": "numbers", "kd": "numbers", "dt": "number", "low": "numbers", "high": "numbers"},
}
KEY_TYPES = {"str": "a string", "int": "a whole number", "number": "a number", "numbers": "numbers",
             "object": "an object"}


def _fits(value: Any, kind: str) -> bool:
    if kind == "str":
        return isinstance(value, str)
    if kind == "object":
        return isinstance(value, dict)
    if kind in ("int", "number"):
        numeric = isinstance(value, int) if kind == "int" else isinstance(value, (int, float))
        return numeric and not isinstance(value, bool) and bool(np.isfinite(value))
    try:  # numbers: a number or a (nested, rectangular) list of them, which bounds may hold as +-inf
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        return False
    return array.size > 0 and not np.isnan(array).any() and not isinstance(value, (str, bool, dict))


def check_keys(run_dir: Path, meta: dict, keys: dict[str, str]) -> None:
    """Refuse a policy.json that lacks a key its type needs or holds the wrong type there.

    Raises:
        MotorlabError: "runs/x/policy.json: key 'obs_dim' is missing; re-run training."
    """
    for key, kind in keys.items():
        if key not in meta:
            raise MotorlabError(f"{run_dir / POLICY_JSON}: key {key!r} is missing; re-run training.")
        if not _fits(meta[key], kind):
            raise _bad_key(run_dir, key, meta[key], KEY_TYPES[kind])


def _space(run_dir: Path, meta: dict, key: str) -> gym.Space:
    """The space policy.json records under `key`, one line naming the key where it is damaged."""
    try:
        return decode_space(meta[key])
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError, AssertionError) as e:
        raise MotorlabError(f"{run_dir / POLICY_JSON}: key {key!r} does not describe a space ({type(e).__name__}: "
                            f"{' '.join(str(e).split())}); re-run training.") from None


def _bad_key(run_dir: Path, key: str, value: Any, wanted: str) -> MotorlabError:
    shown = repr(value)
    shown = shown if len(shown) <= 40 else shown[:37] + "..."
    return MotorlabError(f"{run_dir / POLICY_JSON}: key {key!r} holds {shown}, not {wanted}; re-run training.")


def load_policy(spec: str, env: gym.Env, env_id: str, seed: int = 0) -> Policy:
    """A policy from a run folder or a built-in spec (see module doc), for `env`.

    Raises:
        MotorlabError: unknown spec, missing or corrupt run folder.
    """
    head = spec.split(":", 1)[0]
    if head == "pid":
        return pid_for_env(spec, env, env_id)  # Box actions only, one line otherwise
    if spec == "zero":
        return ZeroPolicy(env.action_space, env_id)
    if spec == "random":
        return RandomPolicy(env.action_space, seed, env_id)
    path = Path(spec)
    if not path.exists():
        raise MotorlabError(unknown_policy_message(spec))
    return load_run_policy(path)


BUILTIN_POLICIES = ("pid", "zero", "random")


def unknown_policy_message(spec: str) -> str:
    return (f"policy {spec!r} is neither a run folder nor a built-in controller; "
            "give a run folder from `motorlab train`, or pid, pid:kp=[...],kd=[...], zero, random.")
