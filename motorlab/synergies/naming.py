"""The muscle names of a synergy set: saved in it (motorlab's fits), or read from the model of the env it
was fitted on (a SAR saved without names: MyoSuite's published ones, older files)."""

from __future__ import annotations

from typing import Any

from motorlab.errors import MotorlabError


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
    from motorlab.evaluation.activations import resolve_signal, signal_bounds, signal_names

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
