"""Training checkpoints, pickle-free, so that `motorlab train --resume RUN_DIR` continues a run
that was killed (even with SIGKILL) to the same total budget.

    RUN_DIR/checkpoint/latest.json         step counter, tracker state, the files below (written last)
    RUN_DIR/checkpoint/model-<steps>.safetensors   networks' and optimizers' tensors
    RUN_DIR/checkpoint/model-<steps>.json  the rest of their state dicts (optimizer settings, step counts)
    RUN_DIR/checkpoint/buffer-<steps>.npz  the replay buffer (off-policy: SAC, TD3, TQC, CrossQ): arrays; a Dict
                                           observation's per key ("observations.<key>"); with --her,
                                           HerReplayBuffer's episode bounds (ep_start, ep_length)
    RUN_DIR/checkpoint/normalize-<steps>.npz   VecNormalize's running mean, variance and count

Nothing here is a pickle: SB3's own model.zip and torch.save files unpickle when loaded, so
state dicts are split into tensors (safetensors) and plain values (JSON). Each file is written atomically
and latest.json names a complete set, so a kill at any moment leaves the previous checkpoint
usable. Episodes in progress at the checkpoint are not restored: resumed training starts new ones
(HER's buffer closes the episodes it was recording, as SB3's truncate_last_trajectory does).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_bytes, atomic_write_npz, read_json, write_json

if TYPE_CHECKING:  # torch, safetensors and SB3 are imported where a checkpoint is written or read:
    import torch  # a sweep, tune or study process asks `has_checkpoint` of its trials without them
    from stable_baselines3.common.base_class import BaseAlgorithm

FOLDER = "checkpoint"
LATEST = "latest.json"
BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")
HER_ARRAYS = ("ep_start", "ep_length")  # HerReplayBuffer's episode bounds, row by row
HER_CURRENT = "_current_ep_start"  # where each env's episode in progress started


def save_checkpoint(run_dir: Path, model: BaseAlgorithm, monitor_state: dict[str, Any]) -> int:
    """Write a checkpoint of `model` at its current step count; returns that count."""
    import safetensors.torch
    from stable_baselines3.common.vec_env import VecNormalize

    folder = Path(run_dir) / FOLDER
    steps = int(model.num_timesteps)
    tag = f"{steps:012d}"
    _, variables = model._get_torch_save_params()
    tensors: dict[str, torch.Tensor] = {}
    structure = {"params": _split(model.get_parameters(), "params", tensors),
                 "variables": {name: _split(_attr(model, name).detach().cpu(), f"variables/{name}", tensors)
                               for name in variables}}
    files = {"model": f"model-{tag}.safetensors", "model_json": f"model-{tag}.json"}
    atomic_write_bytes(folder / files["model"], safetensors.torch.save(tensors))
    write_json(folder / files["model_json"], structure)
    rb = getattr(model, "replay_buffer", None)
    if rb is not None:
        files["buffer"] = f"buffer-{tag}.npz"
        atomic_write_npz(folder / files["buffer"], pos=np.array(rb.pos), full=np.array(rb.full), **_buffer_arrays(rb))
    venv = model.get_env()
    if isinstance(venv, VecNormalize):
        files["normalize"] = f"normalize-{tag}.npz"
        atomic_write_npz(folder / files["normalize"], **_statistics(venv.obs_rms))
    write_json(folder / LATEST, {"steps": steps, "n_updates": int(getattr(model, "_n_updates", 0)),
                                 "episode_num": int(getattr(model, "_episode_num", 0)), "files": files,
                                 "monitor": monitor_state})
    for old in folder.iterdir():  # earlier checkpoints, now that this one is complete
        if old.name != LATEST and old.name not in files.values():
            old.unlink(missing_ok=True)
    return steps


def has_checkpoint(run_dir: Path) -> bool:
    return (Path(run_dir) / FOLDER / LATEST).is_file()


def load_checkpoint(run_dir: Path, model: BaseAlgorithm) -> dict[str, Any]:
    """Restore networks, optimizers, replay buffer, normalization and step counter into
    `model` (built from the run's config.toml); returns the checkpoint's record.

    Raises:
        MotorlabError: a damaged checkpoint or one from other settings.
    """
    import safetensors.torch
    from safetensors import SafetensorError

    folder = Path(run_dir) / FOLDER
    record = read_json(folder / LATEST)
    try:
        tensors = safetensors.torch.load((folder / record["files"]["model"]).read_bytes())
        structure = read_json(folder / record["files"]["model_json"])
        model.set_parameters(_join(structure["params"], tensors), exact_match=True)
        for name, node in structure["variables"].items():
            _attr(model, name).data.copy_(_join(node, tensors))
        if "buffer" in record["files"]:
            with np.load(folder / record["files"]["buffer"], allow_pickle=False) as z:
                _restore_buffer(model.replay_buffer, z)
        if "normalize" in record["files"]:
            venv = model.get_env()
            with np.load(folder / record["files"]["normalize"], allow_pickle=False) as z:
                _restore_statistics(venv.obs_rms, z)
    except (OSError, KeyError, TypeError, ValueError, RuntimeError, MotorlabError, SafetensorError) as e:
        raise MotorlabError(f"the checkpoint in {folder} is damaged or from other settings ({type(e).__name__}: "
                            f"{str(e).splitlines()[0] if str(e) else ''}); delete {folder} to start the run over.") from None
    model.num_timesteps = int(record["steps"])
    model._n_updates = record["n_updates"]
    model._episode_num = record["episode_num"]
    return record


def _statistics(obs_rms: Any) -> dict[str, np.ndarray]:
    """VecNormalize's running statistics as named arrays: mean, var, count, or per key of a Dict
    observation ("mean.<key>", ...; VecNormalize keeps one RunningMeanStd per key)."""
    if isinstance(obs_rms, dict):
        return {f"{name}.{key}": np.asarray(getattr(rms, name)) for key, rms in obs_rms.items()
                for name in ("mean", "var", "count")}
    return {"mean": obs_rms.mean, "var": obs_rms.var, "count": np.array(obs_rms.count)}


def _restore_statistics(obs_rms: Any, z: Any) -> None:
    """The inverse of _statistics."""
    for key, rms in (obs_rms.items() if isinstance(obs_rms, dict) else [("", obs_rms)]):
        suffix = f".{key}" if key else ""
        rms.mean, rms.var, rms.count = z["mean" + suffix], z["var" + suffix], float(z["count" + suffix])


def _buffer_arrays(rb: Any) -> dict[str, np.ndarray]:
    """A replay buffer's rows that hold data (SB3 preallocates a million) as named arrays: a Dict
    observation's keys as "observations.<key>", HER's episode bounds beside them."""
    filled = rb.buffer_size if rb.full else rb.pos
    arrays: dict[str, np.ndarray] = {}
    for name in (*BUFFER_ARRAYS, *HER_ARRAYS):
        value = getattr(rb, name, None)
        if isinstance(value, dict):
            arrays.update({f"{name}.{key}": a[:filled] for key, a in value.items()})
        elif value is not None:
            arrays[name] = value[:filled]
    if hasattr(rb, HER_CURRENT):
        arrays[HER_CURRENT] = getattr(rb, HER_CURRENT)
    return arrays


def _restore_buffer(rb: Any, z: Any) -> None:
    """The inverse of _buffer_arrays, into a buffer built from the same settings."""
    import warnings

    for name in z.files:
        if name in ("pos", "full"):
            continue
        saved = z[name]
        base, _, key = name.partition(".")
        if base not in (*BUFFER_ARRAYS, *HER_ARRAYS, HER_CURRENT):
            raise KeyError(f"unknown buffer array {name}")
        target = getattr(rb, base)[key] if key else getattr(rb, base)
        target[: len(saved)] = saved
    rb.pos, rb.full = int(z["pos"]), bool(z["full"])
    if hasattr(rb, "truncate_last_trajectory"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # its notice says what is meant here: the episodes being recorded end
            rb.truncate_last_trajectory()


def _split(obj: Any, key: str, tensors: dict[str, torch.Tensor]) -> Any:
    """A nested state dict as JSON, its tensors moved to `tensors` under path-like keys.
    Dicts keep their key types (optimizer states are keyed by int), tuples become lists."""
    import torch

    if isinstance(obj, torch.Tensor):
        tensors[key] = obj.detach().cpu().contiguous()
        return {"tensor": key}
    if isinstance(obj, dict):
        return {"dict": [[k, _split(v, f"{key}/{k}", tensors)] for k, v in obj.items()]}
    if isinstance(obj, (list, tuple)):
        return {"list": [_split(v, f"{key}/{i}", tensors) for i, v in enumerate(obj)]}
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return {"value": obj}
    raise TypeError(f"cannot checkpoint a {type(obj).__name__} at {key}")


def _join(node: dict[str, Any], tensors: dict[str, torch.Tensor]) -> Any:
    """The inverse of _split."""
    if "tensor" in node:
        return tensors[node["tensor"]]
    if "dict" in node:
        return {k: _join(v, tensors) for k, v in node["dict"]}
    if "list" in node:
        return [_join(v, tensors) for v in node["list"]]
    return node["value"]


def _attr(model: BaseAlgorithm, dotted: str):
    obj = model
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj

