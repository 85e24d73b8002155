"""A synergy set as `compare` and `plot` are given it: a sar.npz or a `synergies fit` run folder (its
sar.npz, and the activations it was fitted to), and its muscle names: saved in it (motorlab's fits), or
read from the model of the env it was fitted on (a SAR saved without names: MyoSuite's published ones)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab.errors import MotorlabError

SAR_FILE = "sar.npz"  # what a fit run folder holds (the fit kind's artifact)


def sar_file(given: str | Path) -> Path:
    """The sar.npz a path names: the file itself, or a fit run folder's."""
    path = Path(given)
    return path / SAR_FILE if path.is_dir() else path


def fitted_activations(given: str | Path) -> Path | None:
    """The activations a fit run folder was fitted to (its config.toml), where they are still there; None for a
    file, a folder with no readable config.toml, or activations since moved."""
    from motorlab.runs import read_config

    folder = Path(given)
    if not folder.is_dir():
        return None
    try:
        source = read_config(folder).get("activations")
    except (MotorlabError, OSError):
        return None
    return Path(source) if source and Path(source).exists() else None


def names_for(sar: Any, names_from: str | None, which: str) -> tuple[list[str], str]:
    """(names, where they came from: "saved" or the env id).

    Raises:
        MotorlabError: no saved names and no --names-from, or an env whose muscles do not fit the SAR."""
    from motorlab.synergies.vectors import vectors_of

    saved = vectors_of(sar).names
    if saved is not None:
        return saved, "saved"
    if names_from is None:
        raise MotorlabError(f"{which} was saved without muscle names (a published or older SAR): give --names-from "
                            "ENV_ID, the env whose model it was fitted on (e.g. myoHandReorient8-v0), to read them.")
    from motorlab.envs import EnvConfig, make_env
    from motorlab.synergy_runs.activations import resolve_signal, signal_bounds, signal_names

    env = make_env(EnvConfig(id=names_from))
    try:
        recorded = sar.metadata.get("signal")
        signal = resolve_signal(env, recorded if recorded in ("act", "ctrl", "action") else "auto")
        names = signal_names(env, signal, len(signal_bounds(env, signal)[0]))
    finally:
        env.close()
    if len(names) != sar.n_muscles:
        raise MotorlabError(f"--names-from {names_from} has {len(names)} muscles and {which} decodes to "
                            f"{sar.n_muscles}: name an env with the SAR's body.")
    return names, names_from
