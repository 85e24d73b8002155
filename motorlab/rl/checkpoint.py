"""Training checkpoints, pickle-free, so that `motorlab train --resume RUN_DIR` continues a run
that was killed (even with SIGKILL) to the same total budget.

    RUN_DIR/checkpoint/latest.json         step counter, tracker state, the files below (written last)
    RUN_DIR/checkpoint/model-<steps>.pt    networks and optimizers: torch state dicts, read back with
                                           torch.load(weights_only=True), which refuses arbitrary objects
    RUN_DIR/checkpoint/buffer-<steps>.npz  the replay buffer (SAC, TD3): plain arrays
    RUN_DIR/checkpoint/normalize-<steps>.npz   VecNormalize's running mean, variance and count

SB3's own model.zip is not used here: loading it unpickles. Each file is written atomically
and latest.json names a complete set, so a kill at any moment leaves the previous checkpoint
usable. Episodes in progress at the checkpoint are not restored: resumed training starts new ones.
"""

from __future__ import annotations

import io
import pickle  # only for its error class: torch.load(weights_only=True) raises pickle.UnpicklingError
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecNormalize

from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_bytes, atomic_write_npz, read_json, write_json

FOLDER = "checkpoint"
LATEST = "latest.json"
BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def save_checkpoint(run_dir: Path, model: BaseAlgorithm, tracker_state: dict[str, Any]) -> int:
    """Write a checkpoint of `model` at its current step count; returns that count."""
    folder = Path(run_dir) / FOLDER
    steps = int(model.num_timesteps)
    tag = f"{steps:012d}"
    _, variables = model._get_torch_save_params()
    blob = {"params": model.get_parameters(),
            "variables": {name: _attr(model, name).detach().cpu().clone() for name in variables}}
    buf = io.BytesIO()
    torch.save(blob, buf)
    files = {"model": f"model-{tag}.pt"}
    atomic_write_bytes(folder / files["model"], buf.getvalue())
    rb = getattr(model, "replay_buffer", None)
    if rb is not None:
        files["buffer"] = f"buffer-{tag}.npz"
        filled = rb.buffer_size if rb.full else rb.pos  # only what holds data: SB3 preallocates 1M rows
        arrays = {k: getattr(rb, k)[:filled] for k in BUFFER_ARRAYS if getattr(rb, k, None) is not None}
        atomic_write_npz(folder / files["buffer"], pos=np.array(rb.pos), full=np.array(rb.full), **arrays)
    venv = model.get_env()
    if isinstance(venv, VecNormalize):
        files["normalize"] = f"normalize-{tag}.npz"
        atomic_write_npz(folder / files["normalize"], mean=venv.obs_rms.mean, var=venv.obs_rms.var,
                         count=np.array(venv.obs_rms.count))
    write_json(folder / LATEST, {"steps": steps, "n_updates": int(getattr(model, "_n_updates", 0)),
                                 "episode_num": int(getattr(model, "_episode_num", 0)), "files": files,
                                 "tracker": tracker_state})
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
    folder = Path(run_dir) / FOLDER
    record = read_json(folder / LATEST)
    try:
        blob = torch.load(folder / record["files"]["model"], weights_only=True)  # tensors and numbers only
        model.set_parameters(blob["params"], exact_match=True)
        for name, value in blob["variables"].items():
            _attr(model, name).data.copy_(value)
        if "buffer" in record["files"]:
            rb = model.replay_buffer
            with np.load(folder / record["files"]["buffer"], allow_pickle=False) as z:
                for key in BUFFER_ARRAYS:
                    if key in z.files:
                        saved = z[key]
                        getattr(rb, key)[: len(saved)] = saved
                rb.pos, rb.full = int(z["pos"]), bool(z["full"])
        if "normalize" in record["files"]:
            venv = model.get_env()
            with np.load(folder / record["files"]["normalize"], allow_pickle=False) as z:
                venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = z["mean"], z["var"], float(z["count"])
    except (OSError, KeyError, ValueError, RuntimeError, EOFError, pickle.UnpicklingError) as e:
        raise MotorlabError(f"the checkpoint in {folder} is damaged or from other settings ({type(e).__name__}: "
                            f"{str(e).splitlines()[0] if str(e) else ''}); delete {folder} to start the run over.") from None
    model.num_timesteps = int(record["steps"])
    model._n_updates = record["n_updates"]
    model._episode_num = record["episode_num"]
    return record


def _attr(model: BaseAlgorithm, dotted: str):
    obj = model
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj
