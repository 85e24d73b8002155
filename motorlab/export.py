"""`motorlab export`: a policy folder that is safe to share, from a run folder or an SB3 zip.

A motorlab run folder mixes files anyone can open safely (JSON, TOML, CSV, safetensors, PNG)
with SB3's `model.zip`, which unpickles when loaded and so can run code. Exporting a run
copies only the safe files (SHAREABLE) into a new folder, which `motorlab evaluate`,
`video`, `synergies collect` and `zeroshot` use as they use the run itself.

An SB3 zip saved in a notebook (`model.save("ppo.zip")`, maybe with `VecNormalize.save`)
is a pickle; with `trust=True` it is loaded once and written as policy.json +
policy.safetensors, so that it never needs unpickling again.
"""

from __future__ import annotations

import json
import pickle
import shutil
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym

from motorlab import algos
from motorlab.envs import EnvConfig, describe_env, env_record, make_env
from motorlab.envs.spaces import describe_space, flat_space, is_dict, obs_layout
from motorlab.errors import MotorlabError, did_you_mean
from motorlab.policies import (
    decode_classes,
    encode_classes,
    normalization,
    policy_class_name,
    policy_classes,
    save_sb3_policy,
)
from motorlab.runs import CONFIG, SUMMARY, atomic_path, prepare_run_dir, require_run_dir, write_config, write_summary

# Files of a run folder that hold no pickle: what `export` copies and what is safe to send.
SHAREABLE = ("policy.json", "policy.safetensors", CONFIG, "metrics.csv", "environment.json", "faults.log",
             "sar.npz", "activations.npz", "transitions.npz", "model.json", "model.safetensors", "episodes.npz")
SHAREABLE_FOLDERS = ("plots", "videos")
# SB3 policy modules -> motorlab algorithm names, as each algorithm declares them (algos/; A2C's
# policy is PPO's ActorCriticPolicy)
ALGO_OF_MODULE = {module: algo.name for algo in algos.registry().values() if algo.sb3 for module in algo.zip_modules}


def export_run(source: Path, out: Path) -> dict[str, Any]:
    """Copy a finished run's shareable files (no model.zip, checkpoint/ or tensorboard/) to `out`."""
    source = require_run_dir(Path(source))
    _check_distinct(source, out)
    run = prepare_run_dir(out, "export")
    copied = []
    for name in SHAREABLE:
        if (source / name).is_file():
            _copy(source / name, run / name)
            copied.append(name)
    for folder in SHAREABLE_FOLDERS:
        for path in sorted((source / folder).glob("*")) if (source / folder).is_dir() else []:
            if path.is_file() and path.suffix in (".png", ".mp4", ".html", ".txt", ".csv", ".json"):
                _copy(path, run / folder / path.name)
                copied.append(f"{folder}/{path.name}")
    summary = json.loads((source / SUMMARY).read_text())
    summary.update({"exported_from": str(source.resolve()), "exported_files": copied})
    write_summary(run, summary)
    return {**summary, "run_dir": str(run)}


def export_sb3_zip(zip_path: Path, out: Path, trust: bool, env: str | EnvConfig | None = None,
                   vecnormalize: Path | None = None, algo: str | None = None) -> dict[str, Any]:
    """Convert an SB3 model zip (and its VecNormalize pickle) into a pickle-free policy folder.

    Args:
        zip_path: a file written by SB3's `model.save`.
        out: the folder to write (policy.json, policy.safetensors, config.toml, summary.json).
        trust: must be True: loading the zip unpickles it, which runs code from the file.
        env: the env the policy acts in (an id, or an EnvConfig: its id, arguments, history and
            synergies); recorded in config.toml so `motorlab evaluate OUT` needs no --env, and
            checked against the policy's observation and action spaces.
        vecnormalize: the pickle `VecNormalize.save` wrote, if the policy was trained on
            normalized observations (its statistics go into policy.safetensors).
        algo: an SB3 algorithm of motorlab.algos, e.g. ppo (also for A2C), sac, tqc (default: read from
            the zip's JSON, without unpickling).

    Raises:
        MotorlabError: missing or non-SB3 file, trust not given, unsupported policy or space,
            an env whose spaces do not match.
    """
    zip_path = Path(zip_path)
    cfg = EnvConfig(id=env) if isinstance(env, str) else env
    algo = algo or _algo_in_zip(zip_path)
    if vecnormalize is not None and not Path(vecnormalize).is_file():
        raise MotorlabError(f"--vecnormalize {vecnormalize} does not exist; give the file VecNormalize.save wrote.")
    if trust is not True:
        raise MotorlabError(f"exporting {zip_path} means unpickling it (SB3 zips and VecNormalize files are "
                            "pickles), and unpickling runs code from the file. Do it only for files from a source "
                            "you trust, and then pass --trust.")
    _check_distinct(zip_path.parent, out)
    model = _load_zip(zip_path, algo)  # reached only with trust
    vecnorm = _load_vecnormalize(Path(vecnormalize)) if vecnormalize is not None else None
    _check_exportable(model, cfg, vecnorm)

    run = prepare_run_dir(out, "export")
    save_sb3_policy(run, model, algo, vecnorm)
    if cfg is not None:
        write_config(run, {"env": env_record(cfg)})
    summary = {"exported_from": str(zip_path.resolve()), "algo": algo, "env_id": cfg.id if cfg else None,
               "num_timesteps": int(model.num_timesteps), "observation_normalized": vecnorm is not None,
               "exported_files": ["policy.json", "policy.safetensors"] + ([CONFIG] if cfg else [])}
    write_summary(run, summary)
    return {**summary, "run_dir": str(run)}


def _check_distinct(source: Path, out: Path) -> None:
    if out is not None and Path(out).resolve() == Path(source).resolve():
        raise MotorlabError(f"--out {out} is the source folder; export into a new folder.")


def _copy(src: Path, dst: Path) -> None:
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def _algo_in_zip(zip_path: Path) -> str:
    """The algorithm of an SB3 zip, from the plain JSON of its `data` entry (nothing unpickled)."""
    if not zip_path.is_file():
        raise MotorlabError(f"{zip_path} does not exist; give a run folder or a .zip written by SB3's model.save.")
    try:
        with zipfile.ZipFile(zip_path) as z:
            data = json.loads(z.read("data"))
        module = data["policy_class"]["__module__"]
    except (zipfile.BadZipFile, KeyError, TypeError, ValueError, OSError) as e:
        raise MotorlabError(f"{zip_path} is not an SB3 model zip ({type(e).__name__}: {e}); "
                            "give a file written by SB3's model.save.") from None
    if module not in ALGO_OF_MODULE:
        titles = ", ".join(a.title for a in algos.registry().values() if a.sb3)
        raise MotorlabError(f"{zip_path} holds a policy from {module}; motorlab exports {titles} and A2C policies "
                            "(pass --algo if this is one of them).")
    return ALGO_OF_MODULE[module]


def _load_zip(zip_path: Path, algo: str):
    known = {name: a for name, a in algos.registry().items() if a.sb3}
    if algo not in known:
        raise MotorlabError(f"--algo {algo!r}{did_you_mean(algo, known)}: choose {', '.join(known)} (ppo also for "
                            "A2C).")
    try:
        return known[algo].sb3_class().load(zip_path, device="cpu")
    except Exception as e:  # noqa: BLE001  (unpickling can fail in any way; the user needs the one line)
        raise MotorlabError(f"cannot load {zip_path} as {known[algo].title} ({type(e).__name__}: {e}); "
                            "check --algo, and that it was saved with a compatible stable-baselines3.") from None


def _load_vecnormalize(path: Path):
    from stable_baselines3.common.vec_env import VecNormalize

    try:
        with open(path, "rb") as f:
            vecnorm = pickle.load(f)  # what VecNormalize.load does; reached only with trust
    except Exception as e:  # noqa: BLE001
        raise MotorlabError(f"cannot unpickle {path} ({type(e).__name__}: {e}); give the file VecNormalize.save "
                            "wrote.") from None
    if not isinstance(vecnorm, VecNormalize):
        raise MotorlabError(f"{path} holds a {type(vecnorm).__name__}, not SB3's VecNormalize.")
    return vecnorm


def _check_exportable(model, cfg: EnvConfig | None, vecnorm) -> None:
    if policy_class_name(model.policy) is None:
        raise MotorlabError(f"the policy is a {type(model.policy).__name__}; motorlab exports MLP policies "
                            f"({', '.join(policy_classes())}).")
    obs, act = model.observation_space, model.action_space
    if not (isinstance(obs, gym.spaces.Box) or is_dict(obs)):
        raise MotorlabError(f"the policy's observation space is {describe_space(obs)}; motorlab exports Box and Dict "
                            "observations.")
    obs_layout(obs)  # a Dict of Box entries only (one line naming the key otherwise)
    if not isinstance(act, (gym.spaces.Box, gym.spaces.Discrete)):
        raise MotorlabError(f"the policy's action space is {describe_space(act)}; motorlab exports Box (continuous) "
                            "and Discrete actions.")
    try:
        decode_classes(encode_classes(dict(model.policy_kwargs)))
    except MotorlabError as e:
        raise MotorlabError(f"the policy's policy_kwargs cannot be exported: {e}") from None
    if vecnorm is not None and vecnorm.norm_obs and not is_dict(obs) and vecnorm.obs_rms.mean.shape != obs.shape:
        raise MotorlabError(f"the VecNormalize statistics have shape {vecnorm.obs_rms.mean.shape}, the policy's "
                            f"observations {obs.shape}; give the file saved with this model.")
    if vecnorm is not None and is_dict(obs) and not isinstance(vecnorm.obs_rms, dict):
        raise MotorlabError("the VecNormalize statistics are of one array, the policy's observations a Dict; give the "
                            "file saved with this model.")
    normalization(vecnorm, obs)  # every key normalized, or one line
    if cfg is not None:
        env = make_env(cfg, shaped=False)  # its observations flat (and stacked, --history), as the policy is given them
        try:
            for name, have, want in (("observation", env.observation_space, flat_space(obs)),
                                     ("action", env.action_space, act)):
                if have.shape != want.shape or describe_space(have) != describe_space(want):
                    what = ((f"of shape {have.shape}", want.shape) if isinstance(have, gym.spaces.Box)
                            and isinstance(want, gym.spaces.Box) else (describe_space(have), describe_space(want)))
                    raise MotorlabError(f"{describe_env(cfg)} has {name}s {what[0]}, the policy {what[1]}; give "
                                        "the env it was trained on (its --history and --sar too).")
        finally:
            env.close()
