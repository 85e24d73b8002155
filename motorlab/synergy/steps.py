"""The synergy steps behind `motorlab synergies vaf|fit|import-sklearn`: read
activations.npz safely, compute, write a run folder."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.runs import prepare_run_dir, write_config, write_summary

SAR_FILE = "sar.npz"


def load_activations(path: Path) -> tuple[np.ndarray, dict]:
    """Activations (n_samples, n_muscles) and metadata from activations.npz (no pickle).

    Raises:
        MotorlabError: missing, not an npz, no `activations` array, wrong shape, NaN/Inf.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "activations.npz"
    if not path.is_file():
        raise MotorlabError(f"{path} does not exist; write it with `motorlab synergies collect RUN_DIR`.")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):  # a plain .npy array
            raise MotorlabError(f"{path} is a single array, not an .npz archive; write it with "
                                "`motorlab synergies collect` (activations.npz).")
        with loaded as data:
            if "activations" not in data.files:
                raise MotorlabError(f"{path} has no 'activations' array; it holds {', '.join(data.files) or 'nothing'}.")
            acts = np.asarray(data["activations"], dtype=np.float64)
            meta = json.loads(str(data["metadata"])) if "metadata" in data.files else {}
    except MotorlabError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, json.JSONDecodeError) as e:
        raise MotorlabError(f"{path} is not a readable .npz file ({e}); collect it again.") from None
    if acts.ndim != 2 or acts.shape[0] < 2 or acts.shape[1] < 1:
        raise MotorlabError(f"{path}: activations must be (samples, muscles) with at least 2 samples; got {acts.shape}.")
    if not np.all(np.isfinite(acts)):
        raise MotorlabError(f"{path}: activations contain NaN or Inf; collect them again.")
    return acts, meta


def vaf_step(activations: Path, threshold: float = 0.8, method: str = "pca", max_n: int | None = None,
             out: Path | None = None) -> dict[str, Any]:
    """VAF for N = 1..n_muscles; writes vaf.png and summary.json (`vaf`, `n_for_threshold`)."""
    from motorlab.report.plots import vaf_plot
    from motorlab.synergy.sar import smallest_n, vaf_curve

    if not 0.0 < threshold <= 1.0:
        raise MotorlabError(f"--threshold must be a fraction in (0, 1], e.g. 0.8; got {threshold}.")
    acts, meta = load_activations(activations)
    curve = vaf_curve(acts, method=method, max_n=max_n)
    try:
        n_needed: int | None = smallest_n(curve, threshold)
    except MotorlabError:
        n_needed = None  # reported as null; the curve is still worth having
    run = prepare_run_dir(out, "vaf")
    write_config(run, {"activations": str(Path(activations).resolve()), "threshold": threshold, "method": method,
                       "max_n": max_n})
    vaf_plot(curve, threshold, n_needed, run / "vaf.png", f"VAF of {meta.get('env_id', 'recorded')} activations ({method})")
    summary = {"method": method, "n_muscles": int(acts.shape[1]), "samples": int(acts.shape[0]),
               "threshold": threshold, "n_for_threshold": n_needed, "vaf": [float(v) for v in curve]}
    write_summary(run, summary)
    summary["run_dir"] = str(run)
    return summary


def fit_step(activations: Path, n_synergies: int | None = None, vaf: float | None = None, method: str = "pca-ica",
             seed: int = 0, out: Path | None = None) -> dict[str, Any]:
    """Fit a SAR and write `sar.npz` + summary.json in the run folder."""
    from motorlab.synergy.sar import fit_sar, save_sar

    acts, meta = load_activations(activations)
    sar = fit_sar(acts, n_synergies=n_synergies, vaf=vaf, method=method, seed=seed, source_env=meta.get("env_id"))
    run = prepare_run_dir(out, "fit")
    write_config(run, {"activations": str(Path(activations).resolve()), "n_synergies": n_synergies, "vaf": vaf,
                       "method": method, "seed": seed})
    save_sar(sar, run / SAR_FILE)
    summary = {"sar": str(run / SAR_FILE), "method": method, "n_synergies": sar.n_synergies,
               "n_muscles": sar.n_muscles, "vaf": sar.metadata.get("vaf"), "source_env": meta.get("env_id"),
               "samples": int(acts.shape[0])}
    write_summary(run, summary)
    summary["run_dir"] = str(run)
    return summary
