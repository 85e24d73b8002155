"""`motorlab export RUN --onnx`: a run's policy as one ONNX file, for a robot that has no torch.

The graph holds everything between the robot's raw observation and the command it sends:

    obs ─► history stack (K > 1) ─► normalization (obs_rms, clip) ─► the policy's deterministic
        action (PPO: the mean, clipped to the action box; SAC/TD3/TQC/CrossQ: tanh, unscaled to the
        box; each algorithm's file in motorlab/algos/ says how its actor computes it)
        ─► SAR decode (runs acting in synergy space) ─► action

so that onnxruntime and numpy are all a robot needs (docs/deployment.md; examples/onnx_runner.py).
Inputs and outputs (float32 unless said, dynamic batch dimension "batch"):

    obs             [batch, D]     the newest observation, as the env gives it (not normalized)
    obs_stack       [batch, K*D]   K > 1 only: the last stack, oldest observation first; at an
                                   episode's start, the first observation repeated K times
    action          [batch, A]     what the env (robot) takes; int64 [batch] for Discrete actions:
                                   the index of the deterministic policy's action (the most likely)
    next_obs_stack  [batch, K*D]   K > 1 only: feed it back as obs_stack at the next step

A recurrent policy (RecurrentPPO) carries its state explicitly, an input/output pair per state
(`lstm_h` / `next_lstm_h`, `lstm_c` / `next_lstm_c`, [layers, batch, hidden]): zeros at an
episode's start, else the previous step's outputs. The sidecar lists them with the rest, and
the check runs the graph over several steps, feeding the states back, against the policy's own.

A policy trained on a Dict observation (goal-conditioned tasks) takes it flattened, one input:
`obs` is the keys' values one after another in `obs_layout` order (the Dict's key order,
`gymnasium.spaces.flatten`'s), each raveled; the sidecar lists each key's slice. The graph splits
it into the keys its network was trained on. One flat input, rather than one input per key, keeps
the interface of every motorlab graph the same and the history stack (flat by then) possible.

The stack lives in the graph, not in the caller: the order and the reset padding are the
training env's (Gymnasium's FrameStackObservation, padding_type="reset"), and a caller cannot
get them wrong. What the training env adds to model the robot (low-pass delay, latency, noise,
pushes) or to score the task (reward shaping) is not in the graph: the robot brings its own, and
the sidecar lists them under `not_in_graph`.

The exporter is torch's TorchScript one (`dynamo=False`): for these small MLPs it needs only
the `onnx` package (the dynamo exporter also needs onnxscript and onnx-ir), writes opset 17 /
IR 8 that older onnxruntime builds on robots read, takes milliseconds and prints nothing. Before
anything is written, onnxruntime runs the graph on observations from the env and random ones,
and its actions must equal `SB3Policy.act`'s (plus the SAR decode) to TOLERANCE.
"""

from __future__ import annotations

import json
import tomllib
import warnings
from importlib import metadata
from pathlib import Path
from types import ModuleType
from typing import Any

import gymnasium as gym
import numpy as np

from motorlab.algos.base import StateSpec
from motorlab.envs import EnvConfig, env_dt, make_env
from motorlab.envs.spaces import KeySlice, describe_space, layout_json
from motorlab.errors import MotorlabError
from motorlab.extras import missing
from motorlab.policies import BUILTIN_POLICIES, POLICY_JSON, SB3Policy, load_policy_files
from motorlab.runs import CONFIG, atomic_write_bytes, read_json, require_run_dir, write_json
from motorlab.synergies.wrapper import SynergyActionWrapper

ONNX_FILE = "policy.onnx"
SIDECAR = "policy.onnx.json"  # the interface and the export check, for people and for tools
FORMAT = "motorlab-onnx-policy/1"
OPSET = 17
TOLERANCE = 1e-5  # largest |onnxruntime - torch| allowed on any action element (float32)
RANDOM_OBSERVATIONS = 256
ENV_STEPS = 200  # observations from env steps for the check: a few episodes, a second or so
DYNAMIC = "batch"
RECURRENT_ROWS = 8  # a recurrent policy is checked on this many rows at a time, step after step
# EnvConfig fields the graph implements, or that say nothing about the policy's inputs and outputs
IN_GRAPH = {"id", "history", "sar", "phi", "kwargs", "success"}


def export_onnx(run_dir: Path, out: Path, seed: int = 0) -> dict[str, Any]:
    """Write a run's policy as `out/policy.onnx` and its interface as `out/policy.onnx.json`.

    Args:
        run_dir: a finished run folder holding an SB3 policy (any in motorlab/algos/, and A2C), from
            `motorlab train` or `motorlab export`.
        out: the folder to write (created if needed; may be the run folder itself).
        seed: seeds the env episodes and random observations of the check.

    Returns:
        The summary: `files` (paths written), `onnx`, `sidecar`, `inputs`, `outputs` (name,
        shape, dtype, description each), `max_abs_error` (onnxruntime against torch),
        `tolerance`, `checked_observations`, `env_observations`, `opset`, `ir_version`, `algo`,
        `env_id`, `history`, `dt` (seconds per env step), `observation_size`, `action_size`,
        `normalized`, `sar`, `phi`, `not_in_graph`, `exported_from`, `versions`, `format`.

    Raises:
        MotorlabError: not a finished run folder, a run without an SB3 policy (PID, LQR,
            evaluate runs), a policy the graph cannot express, onnx or onnxruntime missing,
            or onnxruntime's actions differ from torch's by more than TOLERANCE. Nothing is
            written then, and files already in `out` stay as they were.
    """
    run_dir = _require_run(run_dir)
    out = _out_dir(out)
    meta = _sb3_meta(run_dir)
    onnx, ort = _require_onnx()
    env_cfg = _env_config(run_dir)
    history = env_cfg.history if env_cfg else 1
    policy = load_policy_files(run_dir)
    assert isinstance(policy, SB3Policy)  # _sb3_meta checked the type
    obs_size = _observation_size(policy, history)
    env = make_env(env_cfg, shaped=False) if env_cfg else None
    try:
        decode = _synergy_decode(env) if env_cfg and env_cfg.sar else None
        stacks = _env_stacks(env, policy, seed) if env is not None else np.zeros((0, obs_size * history), np.float32)
        dt = env_dt(env) if env is not None else None  # the control period the policy was trained at
    finally:
        if env is not None:
            env.close()
    states = policy.algorithm.onnx_states(policy.policy)  # a recurrent policy's state pairs (else none)
    module = _deployed_module(policy, meta, history, obs_size, decode)
    model = onnx.load_from_string(_to_onnx(module, history, obs_size, states))
    stacks = np.concatenate([stacks, _random_stacks(policy, stacks, RANDOM_OBSERVATIONS, seed)])
    error = _check(ort, model.SerializeToString(), policy, decode, stacks, history, obs_size, states)

    space = policy.policy.action_space
    discrete = isinstance(space, gym.spaces.Discrete)
    action_size = int(decode.size if decode else 1 if discrete else space.shape[0])
    inputs, outputs = _interface(obs_size, history, action_size, policy.layout, space, states)
    not_in_graph = _not_in_graph(env_cfg)
    info = {
        "format": FORMAT, "onnx": ONNX_FILE, "inputs": inputs, "outputs": outputs, "opset": OPSET,
        "ir_version": int(model.ir_version), "algo": meta.get("algo"), "env_id": env_cfg.id if env_cfg else None,
        "history": history, "dt": dt, "observation_size": obs_size, "action_size": action_size,
        "action_space": describe_space(space), "obs_layout": layout_json(policy.policy.observation_space),
        "normalized": policy.obs_mean is not None, "sar": env_cfg.sar if env_cfg else None,
        "phi": env_cfg.phi if env_cfg and env_cfg.sar else None, "not_in_graph": not_in_graph,
        "max_abs_error": error, "tolerance": 0.0 if discrete else TOLERANCE, "checked_observations": len(stacks),
        "env_observations": len(stacks) - RANDOM_OBSERVATIONS, "exported_from": str(run_dir.resolve()),
        "versions": {name: _version(name) for name in ("torch", "onnx", "onnxruntime", "stable-baselines3")},
    }
    _add_metadata(model, info)
    onnx.checker.check_model(model)
    # the graph first, then its description: a sidecar never describes a graph that is not there
    atomic_write_bytes(out / ONNX_FILE, model.SerializeToString())
    write_json(out / SIDECAR, info)
    return {**info, "files": [str(out / ONNX_FILE), str(out / SIDECAR)], "onnx": str(out / ONNX_FILE),
            "sidecar": str(out / SIDECAR)}


# ---- what can be exported ------------------------------------------------------------

def _require_run(run_dir: Path) -> Path:
    run_dir = Path(run_dir)
    if str(run_dir).split(":", 1)[0] in BUILTIN_POLICIES and not run_dir.exists():
        raise MotorlabError(f"{run_dir} is a built-in controller, not a run folder; --onnx exports the neural "
                            f"policy of a run folder from `motorlab train` ({_sb3_titles()}).")
    return require_run_dir(run_dir)


def _out_dir(out: Path) -> Path:
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MotorlabError(f"--out {out} is a file; give a folder (policy.onnx and {SIDECAR} are written in it).")
    return out


def _sb3_meta(run_dir: Path) -> dict[str, Any]:
    """policy.json of a run with an SB3 policy; any other run is one clear error."""
    if not (run_dir / POLICY_JSON).is_file():
        raise MotorlabError(f"{run_dir} holds no policy ({POLICY_JSON} is missing); --onnx exports the policy "
                            "of a run folder from `motorlab train`.")
    meta = read_json(run_dir / POLICY_JSON)
    kind = meta.get("type")
    if kind in ("pid", "lqr"):
        raise MotorlabError(f"{run_dir} holds {'an LQR' if kind == 'lqr' else 'a PID'} controller, not a neural policy; --onnx exports "
                            f"{_sb3_titles()} policies (a linear controller is a few lines on the robot: its "
                            f"gains are in {run_dir / POLICY_JSON}).")
    if kind != "sb3":
        raise MotorlabError(f"{run_dir / POLICY_JSON} has policy type {kind!r}; --onnx exports "
                            f"{_sb3_titles()} policies.")
    return meta


def _sb3_titles() -> str:
    from motorlab import algos

    return ", ".join(a.title for a in algos.registry().values() if a.sb3)


def _require_onnx() -> tuple[ModuleType, ModuleType]:
    """onnx and onnxruntime, or the error that says how to install them."""
    try:
        import onnx
        import onnxruntime
    except ImportError as e:
        raise missing(f"motorlab export --onnx needs {e.name or 'onnx'}", "onnx") from None
    return onnx, onnxruntime


def _env_config(run_dir: Path) -> EnvConfig | None:
    """The env the policy was trained in, from config.toml (None: an imported zip without --env)."""
    try:
        config = tomllib.loads((run_dir / CONFIG).read_text())
    except (OSError, ValueError):
        return None
    env = config.get("env")
    if not isinstance(env, dict) or not env.get("id"):
        return None
    try:
        return EnvConfig(**env)
    except ValueError as e:
        raise MotorlabError(f"{run_dir / CONFIG}: its [env] settings are not valid ({e.__class__.__name__}); "
                            "re-run training.") from None


def _observation_size(policy: SB3Policy, history: int) -> int:
    shape = policy.observation_space.shape  # flat: a Dict observation's keys one after another
    if len(shape) != 1 or shape[0] % history:
        raise MotorlabError(f"the policy's observations have shape {shape}, which is not {history} stacked "
                            "flat observations; --onnx exports policies on flat (Box) or Dict observations.")
    space = policy.policy.action_space
    if not (isinstance(space, gym.spaces.Box) and len(space.shape) == 1) and not isinstance(space, gym.spaces.Discrete):
        raise MotorlabError(f"the policy's action space is {describe_space(space)}; --onnx exports flat Box and "
                            "Discrete actions.")
    return shape[0] // history


def _not_in_graph(env_cfg: EnvConfig | None) -> list[str]:
    """The training env's settings that are not the policy's: they model the robot (delay, latency,
    noise, pushes, fatigue) or score the task (reward), so the robot brings them itself."""
    if env_cfg is None:
        return []
    return [f"{name} = {getattr(env_cfg, name)!r}" for name, field in EnvConfig.model_fields.items()
            if name not in IN_GRAPH and getattr(env_cfg, name) != field.get_default(call_default_factory=True)]


# ---- the SAR decode ------------------------------------------------------------------

class _Decode:
    """The affine synergy decode of a SynergyActionWrapper, as plain arrays."""

    def __init__(self, wrapper: SynergyActionWrapper):
        self.wrapper = wrapper
        self.matrix, self.bias = np.asarray(wrapper._matrix), np.asarray(wrapper._bias)
        self.clip = bool(wrapper._clip)
        self.low, self.high = np.asarray(wrapper._low), np.asarray(wrapper._high)
        self.size = self.matrix.shape[1]

    def __call__(self, actions: np.ndarray) -> np.ndarray:
        """What the env receives for each row of policy actions: the wrapper's own code."""
        return np.stack([self.wrapper.action(a) for a in actions]).astype(np.float32)


def _synergy_decode(env: gym.Env) -> _Decode:
    layer = env
    while isinstance(layer, gym.Wrapper):
        if isinstance(layer, SynergyActionWrapper):
            return _Decode(layer)
        layer = layer.env
    raise MotorlabError("the run's env acts in synergy space, but its env has no synergy wrapper; re-run training.")


# ---- the graph -----------------------------------------------------------------------

def _deployed_module(policy: SB3Policy, meta: dict, history: int, obs_size: int, decode: _Decode | None):
    """A torch module computing what `SB3Policy.act` (and the SAR decode) computes, stack included."""
    import torch
    from stable_baselines3.common.distributions import (
        CategoricalDistribution,
        DiagGaussianDistribution,
        SquashedDiagGaussianDistribution,
        StateDependentNoiseDistribution,
    )
    from stable_baselines3.common.preprocessing import preprocess_obs

    sb3 = policy.policy
    algo = policy.algorithm  # how its actor computes the deterministic action (motorlab/algos/)
    n_states = len(algo.onnx_states(sb3))
    dist = getattr(sb3, "action_dist", None) or getattr(getattr(sb3, "actor", None), "action_dist", None)
    discrete = isinstance(dist, CategoricalDistribution)  # its deterministic action: the most likely index
    if algo.tanh_in_actor or discrete:
        squash = False  # TD3's actor ends in tanh itself
    elif isinstance(dist, SquashedDiagGaussianDistribution):
        squash = True
    elif isinstance(dist, StateDependentNoiseDistribution):
        squash = dist.bijector is not None  # gSDE's deterministic action is tanh(mean) when it squashes
    elif isinstance(dist, DiagGaussianDistribution):
        squash = False
    else:
        raise MotorlabError(f"the policy's action distribution is {type(dist).__name__}; --onnx exports Gaussian "
                            "policies (on Box actions) and categorical ones (on Discrete actions).")
    space = sb3.action_space
    layout = policy.layout  # a Dict observation: each key's slice of the flat input

    def f64(a: Any) -> torch.Tensor:
        return torch.as_tensor(np.asarray(a, dtype=np.float64))

    class DeployedPolicy(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.sb3 = sb3
            self.normalized = policy.obs_mean is not None
            if self.normalized:
                # float64, as SB3Policy.act normalizes (numpy promotes to the statistics' float64)
                self.register_buffer("mean", f64(policy.obs_mean))
                self.register_buffer("std", f64(np.sqrt(policy.obs_var + policy.epsilon)))
            if not discrete:
                self.register_buffer("low", torch.as_tensor(space.low, dtype=torch.float32))
                self.register_buffer("high", torch.as_tensor(space.high, dtype=torch.float32))
            if decode is not None:
                self.register_buffer("decode_matrix", f64(decode.matrix))
                self.register_buffer("decode_bias", f64(decode.bias))
                self.register_buffer("decode_low", f64(decode.low))
                self.register_buffer("decode_high", f64(decode.high))

        def act(self, x: torch.Tensor, states: tuple = ()) -> tuple[torch.Tensor, tuple]:
            if self.normalized:
                x = torch.clamp((x.double() - self.mean) / self.std, -policy.clip_obs, policy.clip_obs).float()
            if layout:  # the flat vector as the Dict the network was trained on (SB3Policy.act's unflatten_batch)
                x = {s.key: x[:, s.start:s.stop].reshape(-1, *s.shape) for s in layout}
            x = preprocess_obs(x, sb3.observation_space, normalize_images=sb3.normalize_images)
            a, states = algo.actor(sb3, x, states)
            if discrete:
                return torch.argmax(a, dim=1), states  # the logits' largest: CategoricalDistribution.mode()
            if squash:
                a = torch.tanh(a)
            # what SB3's predict does with a Box action, in the same float32 operations
            if sb3.squash_output:
                a = self.low + (0.5 * (a + 1.0) * (self.high - self.low))
            else:
                a = torch.minimum(torch.maximum(a, self.low), self.high)
            if decode is not None:
                command = a.double() @ self.decode_matrix + self.decode_bias
                if decode.clip:
                    command = torch.minimum(torch.maximum(command, self.decode_low), self.decode_high)
                a = command.float()
            return a, states

        def forward(self, obs: torch.Tensor, *rest: torch.Tensor):
            # rest: obs_stack (K > 1), then the recurrent states; out: action, next_obs_stack, next states
            states = tuple(rest[len(rest) - n_states:]) if n_states else ()
            if history == 1:
                a, states = self.act(obs, states)
                return (a, *states) if n_states else a
            stack = torch.cat([rest[0][:, obs_size:], obs], dim=1)  # drop the oldest, append the newest
            a, states = self.act(stack, states)
            return a, stack, *states

    return DeployedPolicy().eval()


def _to_onnx(module, history: int, obs_size: int, states: tuple[StateSpec, ...] = ()) -> bytes:
    """The module as ONNX bytes, batch dimension dynamic."""
    import io

    import torch

    inputs, outputs = ["obs"], ["action"]
    args = [torch.zeros(2, obs_size)]
    axes = {"obs": {0: DYNAMIC}, "action": {0: DYNAMIC}}
    if history > 1:
        inputs.append("obs_stack")
        outputs.append("next_obs_stack")
        args.append(torch.zeros(2, obs_size * history))
        axes.update({"obs_stack": {0: DYNAMIC}, "next_obs_stack": {0: DYNAMIC}})
    for spec in states:
        inputs.append(spec.name)
        outputs.append(f"next_{spec.name}")
        args.append(torch.zeros(*(2 if d == DYNAMIC else d for d in spec.shape)))
        batch = {spec.shape.index(DYNAMIC): DYNAMIC}
        axes.update({spec.name: batch, f"next_{spec.name}": batch})
    buffer = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice, tracer notes
        torch.onnx.export(module, tuple(args), buffer, dynamo=False, opset_version=OPSET, input_names=inputs,
                          output_names=outputs, dynamic_axes=axes)
    return buffer.getvalue()


def _interface(obs_size: int, history: int, action_size: int, layout: list[KeySlice],
               space: gym.Space, states: tuple[StateSpec, ...] = ()) -> tuple[list[dict], list[dict]]:
    """The graph's inputs and outputs as the sidecar and metadata_props describe them."""
    stack = history * obs_size
    what = "the newest observation, as the env gives it (not normalized)"
    if layout:
        what = (f"the newest observation, as the env gives it (not normalized), its Dict flattened: "
                f"{', '.join(f'{s.key} [{s.start}:{s.stop}]' for s in layout)} (obs_layout)")
    inputs = [{"name": "obs", "shape": [DYNAMIC, obs_size], "dtype": "float32", "description": what}]
    if isinstance(space, gym.spaces.Discrete):
        outputs = [{"name": "action", "shape": [DYNAMIC], "dtype": "int64",
                    "description": f"the index of the action to send to the env (robot), 0..{int(space.n) - 1}: "
                                   "the deterministic policy's most likely action"}]
    else:
        outputs = [{"name": "action", "shape": [DYNAMIC, action_size], "dtype": "float32",
                    "description": "the action to send to the env (robot), in the env's action units"}]
    if history > 1:
        inputs.append({"name": "obs_stack", "shape": [DYNAMIC, stack], "dtype": "float32",
                       "description": f"the last {history} observations, oldest first: the previous step's "
                                      f"next_obs_stack; at an episode's start, the first observation repeated "
                                      f"{history} times (np.tile(obs, {history}))"})
        outputs.append({"name": "next_obs_stack", "shape": [DYNAMIC, stack], "dtype": "float32",
                        "description": "obs_stack with obs appended and the oldest dropped: feed it back as "
                                       "obs_stack at the next step"})
    for spec in states:
        inputs.append({"name": spec.name, "shape": list(spec.shape), "dtype": "float32",
                       "description": spec.description})
        outputs.append({"name": f"next_{spec.name}", "shape": list(spec.shape), "dtype": "float32",
                        "description": f"{spec.name} after this step: feed it back as {spec.name} at the next step "
                                       "of the same episode"})
    return inputs, outputs


def _add_metadata(model, info: dict[str, Any]) -> None:
    """The interface and the export check in the model's metadata_props (strings; JSON for lists)."""
    model.producer_name = "motorlab"
    model.doc_string = (f"motorlab {info['algo']} policy for {info['env_id']}: see the metadata_props "
                        "'interface' and docs/deployment.md")
    for key, value in info.items():
        entry = model.metadata_props.add()
        entry.key = key
        entry.value = value if isinstance(value, str) else json.dumps(value)
    entry = model.metadata_props.add()
    entry.key, entry.value = "interface", json.dumps({"inputs": info["inputs"], "outputs": info["outputs"]})


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


# ---- the check: onnxruntime against torch ----------------------------------------------

def _env_stacks(env: gym.Env, policy: SB3Policy, seed: int) -> np.ndarray:
    """Observations the policy sees in its own env (stacked as in training), over a few episodes."""
    seen, episode = [], 0
    while len(seen) < ENV_STEPS:
        obs, _ = env.reset(seed=seed + episode)
        policy.reset(1)  # a recurrent policy's state starts from zeros each episode
        episode += 1
        for _ in range(ENV_STEPS - len(seen)):
            obs = np.asarray(obs, dtype=np.float32)
            seen.append(obs)
            obs, _, terminated, truncated, _ = env.step(policy.act(obs[None])[0])
            if terminated or truncated:
                break
    return np.array(seen, dtype=np.float32)


def _random_stacks(policy: SB3Policy, seen: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Stacked observations around the ones the policy knows (its normalization statistics, else
    the env's), inside the observation box, a sixteenth of them far enough out to hit the clip."""
    rng = np.random.default_rng(seed)
    space = policy.observation_space  # flat, a Dict's keys one after another
    if policy.obs_mean is not None:
        center, scale = policy.obs_mean, np.sqrt(policy.obs_var + policy.epsilon)
    elif len(seen) > 1:
        center, scale = seen.mean(axis=0), seen.std(axis=0) + 0.1
    else:
        center, scale = np.zeros(space.shape), np.ones(space.shape)
    z = rng.normal(size=(n, *space.shape))
    z[: n // 16] *= policy.clip_obs + 2.0  # past the normalization's clip
    stacks = np.clip(center + 2.0 * scale * z, space.low, space.high)
    return stacks.astype(np.float32)


def _check(ort: ModuleType, model: bytes, policy: SB3Policy, decode: _Decode | None, stacks: np.ndarray,
           history: int, obs_size: int, states: tuple[StateSpec, ...] = ()) -> float:
    """Largest |onnxruntime - torch| over the actions for `stacks`; raises past TOLERANCE.

    Each row is fed as the graph is fed on a robot: its newest observation as obs, and the
    stack it came from (its oldest observation first, the row shifted by one) as obs_stack.
    A recurrent policy's rows are fed RECURRENT_ROWS at a time, step after step, the graph's
    states fed back as the policy carries its own, so that every step's state is checked too."""
    session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
    rows = RECURRENT_ROWS if states else len(stacks)
    stacks = stacks[: len(stacks) // rows * rows] if states else stacks
    carried = {spec.name: np.zeros([rows if d == DYNAMIC else d for d in spec.shape], np.float32) for spec in states}
    policy.reset(rows)
    got, expected_all, next_stacks = [], [], []
    for start in range(0, len(stacks), rows):
        step = stacks[start:start + rows]
        feed = {"obs": step[:, -obs_size:], **carried}
        if history > 1:
            # the stack before this step: any observation may come first, the rest is the row's oldest K-1
            feed["obs_stack"] = np.concatenate([step[:, -obs_size:], step[:, :-obs_size]], axis=1)
        results = session.run(None, feed)
        carried = {spec.name: out for spec, out in zip(states, results[len(results) - len(states):], strict=True)}
        got.append(results[0])
        expected_all.append(policy.act(step))
        if history > 1:
            next_stacks.append(results[1])
    expected = np.concatenate(expected_all)
    if decode is not None:
        expected = decode(expected)
    got = np.concatenate(got)
    discrete = isinstance(policy.policy.action_space, gym.spaces.Discrete)
    dtype, tolerance = (np.int64, 0.0) if discrete else (np.float32, TOLERANCE)  # action indices must be equal
    if got.shape != expected.shape or got.dtype != dtype:
        raise MotorlabError(f"onnxruntime gives actions of shape {got.shape} ({got.dtype}), torch {expected.shape}; "
                            "policy.onnx not written (a motorlab bug: please report it).")
    error = float(np.max(np.abs(got.astype(np.float64) - expected.astype(np.float64)), initial=0.0))
    if not error <= tolerance:  # NaN fails too
        raise MotorlabError(f"onnxruntime's actions differ from torch's by up to {error:.3g} (tolerance "
                            f"{tolerance:g}) on {len(stacks)} observations; policy.onnx not written (a motorlab "
                            "bug: please report it).")
    if history > 1 and not np.array_equal(np.concatenate(next_stacks), stacks):
        raise MotorlabError("the graph's next_obs_stack is not the training env's observation stack; policy.onnx "
                            "not written (a motorlab bug: please report it).")
    return error
