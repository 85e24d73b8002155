"""Convert a published scikit-learn SAR (joblib pickles) into a plain `sar.npz`.

MyoSuite publishes SARs as three joblib pickles: ``pca.pkl`` (PCA), ``ica.pkl``
(FastICA) and ``normalizer.pkl`` (MinMaxScaler). Unpickling runs arbitrary
code, so this module refuses unless the caller passes ``trust=True``. The
plain arrays are read out, composed into the affine decode map, checked
against scikit-learn's own inverse chain, and only then saved.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.synergy.sar import (
    FORMAT_VERSION,
    SAR,
    SarFormatError,
    affine_from_arrays,
    library_versions,
    require_sklearn,
    save_sar,
    utc_now,
)

PICKLES = {"pca": "pca.pkl", "ica": "ica.pkl", "normalizer": "normalizer.pkl"}
CHECK_ATOL = 1e-6
CHECK_RTOL = 1e-7


def _load_pickle(path: Path, expected: type, pickled_versions: set[str]) -> Any:
    """Unpickle one estimator (callers check trust first); version-mismatch warnings are collected, not shown."""
    import joblib
    from sklearn.exceptions import InconsistentVersionWarning

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", InconsistentVersionWarning)
            obj = joblib.load(path)  # reached only with trust=True, checked in import_sklearn
    except Exception as e:  # an unpickler can raise anything; all of it means "not a usable pickle"
        raise MotorlabError(f"cannot unpickle {path} ({type(e).__name__}: {e}); is it a joblib pickle?") from None
    for w in caught:
        if isinstance(w.message, InconsistentVersionWarning):
            pickled_versions.add(str(w.message.original_sklearn_version))
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)  # keep unrelated warnings
    if not isinstance(obj, expected):
        raise MotorlabError(
            f"{path} holds a {type(obj).__module__}.{type(obj).__name__}, expected a scikit-learn "
            f"{expected.__name__}."
        )
    return obj


def _attr(obj: Any, name: str, path: Path) -> np.ndarray:
    if not hasattr(obj, name):
        raise MotorlabError(f"{path}: the {type(obj).__name__} has no {name}; is it fitted?")
    return np.asarray(getattr(obj, name), dtype=np.float64)


def _json_flag(value: Any) -> bool | str:
    """A whiten setting as JSON: bool or str, keeping its truthiness (sklearn tests `if whiten:`)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, str):
        return value
    return bool(value)


def import_sklearn(folder: Path | str, trust: bool, out: Path | str, n_check: int = 1000, seed: int = 0) -> SAR:
    """Convert ``pca.pkl``, ``ica.pkl``, ``normalizer.pkl`` in `folder` to a plain SAR file.

    Decoding mirrors the installed scikit-learn exactly:
    ``pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))``,
    honouring PCA ``whiten`` (scale by sqrt(explained_variance_)), FastICA
    ``whiten`` (``mean_`` is added back when it is truthy: True, 'warn' from old
    pickles, 'arbitrary-variance', 'unit-variance') and the scaler's feature_range.

    Args:
        folder: folder holding the three joblib pickles.
        trust: must be True: unpickling runs arbitrary code from the files.
        out: the .npz file to write (an existing folder means ``out/sar.npz``).
        n_check: random synergy vectors (uniform in the scaler's feature_range)
            on which motorlab's decode must match scikit-learn's chain.
        seed: seed of those check vectors.

    Returns:
        The imported `SAR` (method "sklearn-import"); metadata holds
        ``import_check_max_abs_error`` and the pickles' sklearn version(s).

    Raises:
        MotorlabError: folder or a pickle missing, trust not given, a pickle of
            the wrong type or shape, or decode disagreeing with scikit-learn
            (nothing is written then).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MotorlabError(f"SAR folder {folder} does not exist or is not a folder; pass the folder holding "
                            f"{', '.join(PICKLES.values())}.")
    paths = {k: folder / name for k, name in PICKLES.items()}
    for path in paths.values():
        if not path.is_file():
            raise MotorlabError(f"{path} is missing; a scikit-learn SAR folder holds {', '.join(PICKLES.values())}.")
    if trust is not True:
        raise MotorlabError(
            f"importing {folder} means unpickling it, and unpickling runs arbitrary code from the files. "
            "Do it only for files from a source you trust, and then pass --trust."
        )
    if isinstance(n_check, bool) or not isinstance(n_check, (int, np.integer)) or n_check < 1:
        raise MotorlabError(f"n_check must be a positive integer; got {n_check!r}.")
    out = Path(out)
    if out.is_dir():
        out = out / "sar.npz"

    sklearn = require_sklearn()
    from sklearn.decomposition import PCA, FastICA
    from sklearn.preprocessing import MinMaxScaler

    versions: set[str] = set()
    pca = _load_pickle(paths["pca"], PCA, versions)
    ica = _load_pickle(paths["ica"], FastICA, versions)
    scaler = _load_pickle(paths["normalizer"], MinMaxScaler, versions)

    arrays = {
        "pca_mean": _attr(pca, "mean_", paths["pca"]),
        "pca_components": _attr(pca, "components_", paths["pca"]),
        "pca_explained_variance": _attr(pca, "explained_variance_", paths["pca"]),
        "ica_mixing": _attr(ica, "mixing_", paths["ica"]),
        "ica_components": _attr(ica, "components_", paths["ica"]),
        "scaler_min": _attr(scaler, "min_", paths["normalizer"]),
        "scaler_scale": _attr(scaler, "scale_", paths["normalizer"]),
    }
    # Mirror FastICA.inverse_transform of the installed sklearn: `if self.whiten: X += self.mean_`.
    # Old pickles (sklearn 1.1/1.2) hold whiten='warn' with _whiten='arbitrary-variance': truthy either way.
    ica_whiten = _json_flag(ica.whiten)
    if ica_whiten:
        arrays["ica_mean"] = _attr(ica, "mean_", paths["ica"])
    else:
        # Without whitening FastICA has no mean_ and adds nothing; zeros keep the file layout fixed.
        arrays["ica_mean"] = np.zeros(arrays["ica_mixing"].shape[0])
    lo, hi = (float(v) for v in scaler.feature_range)
    meta: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "method": "sklearn-import",
        "pca_whiten": bool(pca.whiten),
        "ica_whiten": ica_whiten,
        "ica_whiten_internal": _json_flag(getattr(ica, "_whiten", ica.whiten)),
        "scaler_feature_range": [lo, hi],
        "vaf": (float(np.sum(pca.explained_variance_ratio_)) if hasattr(pca, "explained_variance_ratio_")
                else None),
        "vaf_definition": "sum of the PCA's explained_variance_ratio_ (as pickled)",
        "source_env": None,
        "import_source": str(folder.resolve()),
        "pickled_sklearn_versions": sorted(versions) if versions else [sklearn.__version__],
        "sklearn_versions_differ": bool(versions),
        "created": utc_now(),
        "versions": library_versions(),
    }
    try:
        weight, bias = affine_from_arrays("sklearn-import", arrays, meta)
    except SarFormatError as e:
        raise MotorlabError(f"the pickles in {folder} do not chain together: {e}.") from None
    meta["n_synergies"], meta["n_muscles"] = int(weight.shape[0]), int(weight.shape[1])
    sar = SAR(method="sklearn-import", arrays=arrays, weight=weight, bias=bias, metadata=meta)

    # Verify against scikit-learn's own chain before anything is written.
    x = np.random.default_rng(seed).uniform(lo, hi, size=(int(n_check), sar.n_synergies))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # old-pickle attribute warnings; the numbers are what we check
            expected = pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(x)))
    except Exception as e:  # an estimator from another sklearn version may fail in its own way
        raise MotorlabError(
            f"scikit-learn {sklearn.__version__} cannot run the pickled chain in {folder} "
            f"({type(e).__name__}: {e}); nothing was written."
        ) from None
    got = sar.decode(x)
    expected = np.asarray(expected, dtype=np.float64)
    if got.shape != expected.shape:
        raise MotorlabError(f"decode gives shape {got.shape} but scikit-learn gives {expected.shape}; nothing was written.")
    err = np.abs(got - expected)
    max_err = float(err.max())
    if not np.all(err <= CHECK_ATOL + CHECK_RTOL * np.abs(expected)):
        raise MotorlabError(
            f"the converted SAR disagrees with scikit-learn's inverse chain for {folder} "
            f"(max abs error {max_err:.3g} > {CHECK_ATOL}); nothing was written."
        )
    sar = SAR(method="sklearn-import", arrays=arrays, weight=weight, bias=bias,
              metadata={**meta, "import_check_max_abs_error": max_err, "import_check_n": int(n_check)})
    save_sar(sar, out)
    return sar
