"""Convert a published scikit-learn SAR (joblib pickles) into a plain `sar.npz`.

Two published layouts hold the same PCA -> FastICA -> MinMaxScaler chain:

- the MyoSuite 2.x tutorial: ``pca.pkl``, ``ica.pkl``, ``normalizer.pkl``;
- a MyoSuite 3.0 ``SynergyModel`` folder (``save_synergy_model``): ``pca.pkl``,
  ``ica.pkl``, ``scaler.pkl`` and ``metadata.npz`` (whitened PCA, a [0, 1]
  scaler widened by a margin; the margin lives only in the scaler's numbers).

Unpickling runs arbitrary code, so this module refuses unless the caller passes
``trust=True``. The plain arrays are read out, composed into the affine decode
map, checked against scikit-learn's own inverse chain, and only then saved.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.synergies.sar import (
    FORMAT_VERSION,
    SAR,
    SarFormatError,
    affine_from_arrays,
    library_versions,
    require_sklearn,
    save_sar,
    utc_now,
)

TUTORIAL = "myosuite-2.x-tutorial"
SYNERGY_MODEL = "myosuite-3.0-synergy-model"
# Files of each layout; the last pickle is the MinMaxScaler in both.
FORMATS: dict[str, tuple[str, ...]] = {
    TUTORIAL: ("pca.pkl", "ica.pkl", "normalizer.pkl"),
    SYNERGY_MODEL: ("pca.pkl", "ica.pkl", "scaler.pkl", "metadata.npz"),
}
FORMAT_LABELS = {TUTORIAL: "MyoSuite 2.x tutorial SAR", SYNERGY_MODEL: "MyoSuite 3.0 SynergyModel folder"}
PICKLES = {"pca": "pca.pkl", "ica": "ica.pkl", "normalizer": "normalizer.pkl"}  # the 2.x layout, by role
CHECK_ATOL = 1e-6
CHECK_RTOL = 1e-7


# ------------------------------------------------------------------ which layout


def _listing(fmt: str) -> str:
    return f"{FORMAT_LABELS[fmt]} ({', '.join(FORMATS[fmt])})"


def detect_format(folder: Path) -> str:
    """Which published layout `folder` holds: `TUTORIAL` or `SYNERGY_MODEL`. Opens no file.

    ``normalizer.pkl`` marks the 2.x tutorial, ``scaler.pkl`` or ``metadata.npz`` MyoSuite 3.0.

    Args:
        folder: the folder to look in.

    Returns:
        The format key (a key of `FORMATS`).

    Raises:
        MotorlabError: not a folder, both or neither layout marked, or a file of
            the marked layout missing (the message names it).
    """
    if not folder.is_dir():
        raise MotorlabError(f"SAR folder {folder} does not exist or is not a folder; pass a folder holding a "
                            f"{_listing(TUTORIAL)} or a {_listing(SYNERGY_MODEL)}.")
    has = {name for fmt in FORMATS.values() for name in fmt if (folder / name).is_file()}
    marked = [fmt for fmt, marks in ((TUTORIAL, {"normalizer.pkl"}), (SYNERGY_MODEL, {"scaler.pkl", "metadata.npz"}))
              if has & marks]
    if len(marked) == 2:
        raise MotorlabError(f"{folder} holds both normalizer.pkl (MyoSuite 2.x) and scaler.pkl/metadata.npz "
                            "(MyoSuite 3.0); keep one SAR per folder and import each folder on its own.")
    if not marked:
        gaps = " or ".join(f"{', '.join(n for n in FORMATS[f] if n not in has)} for a {_listing(f)}" for f in FORMATS)
        raise MotorlabError(f"{folder} holds no complete SAR: missing {gaps}.")
    fmt = marked[0]
    missing = [str(folder / n) for n in FORMATS[fmt] if n not in has]
    if missing:
        raise MotorlabError(f"{', '.join(missing)} {'is' if len(missing) == 1 else 'are'} missing; "
                            f"a {_listing(fmt)} holds all of them.")
    return fmt


# ------------------------------------------------------------------ reading


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


def _plain(value: np.ndarray) -> Any:
    """A metadata.npz entry as JSON: numbers and strings as such, NaN/Inf as None, other objects as str."""
    if value.dtype.kind == "O":
        return str(value.item()) if value.ndim == 0 else [str(v) for v in value.ravel()]
    out = value.tolist()
    if isinstance(out, float) and not math.isfinite(out):
        return None
    if isinstance(out, list) and value.dtype.kind == "f":
        return [v if math.isfinite(v) else None for v in value.ravel().tolist()]
    return out


def read_synergy_metadata(path: Path, trust: bool) -> dict[str, Any]:
    """Read a SynergyModel's ``metadata.npz`` as JSON-able values, pickle-free where possible.

    Plain arrays are read with ``allow_pickle=False``. MyoSuite stores
    ``source_clips`` as an object array (a pickle, even when empty); such
    entries are read only when `trust` is True.

    Args:
        path: the metadata.npz file.
        trust: allow unpickling its object arrays.

    Returns:
        {key: value} with numbers, strings, lists and None.

    Raises:
        MotorlabError: not an .npz archive, or object arrays without trust.
    """
    def unreadable(reason: str) -> MotorlabError:
        return MotorlabError(f"cannot read {path} as MyoSuite's metadata.npz ({reason}); re-save the model "
                             "with myosuite's save_synergy_model.")

    plain: dict[str, np.ndarray] = {}
    pickled: list[str] = []
    try:
        npz = np.load(path, allow_pickle=False)
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise unreadable("it is a single .npy array, not an .npz archive")
        with npz:
            for key in npz.files:
                try:
                    plain[key] = npz[key]
                except ValueError as e:
                    if "pickle" not in str(e):
                        raise
                    pickled.append(key)
        if pickled:
            if trust is not True:
                raise MotorlabError(f"{path} stores {', '.join(pickled)} as pickled object arrays, and unpickling "
                                    "runs code from the file; pass --trust only for a source you trust.")
            with np.load(path, allow_pickle=True) as npz:  # trusted: only the object arrays
                plain.update({key: npz[key] for key in pickled})
    except MotorlabError:
        raise
    except Exception as e:  # untrusted bytes: zipfile/zlib/npy-header errors of many types
        raise unreadable(f"{type(e).__name__}: {e}") from None
    return {key: _plain(value) for key, value in plain.items()}


# ------------------------------------------------------------------ the chain


def _chain_arrays(pca: Any, ica: Any, scaler: Any, paths: dict[str, Path]) -> tuple[dict[str, np.ndarray],
                                                                                     dict[str, Any]]:
    """The plain arrays of a fitted PCA -> FastICA -> MinMaxScaler chain and its whiten/range flags."""
    arrays = {
        "pca_mean": _attr(pca, "mean_", paths["pca"]),
        "pca_components": _attr(pca, "components_", paths["pca"]),
        "pca_explained_variance": _attr(pca, "explained_variance_", paths["pca"]),
        "ica_mixing": _attr(ica, "mixing_", paths["ica"]),
        "ica_components": _attr(ica, "components_", paths["ica"]),
        "scaler_min": _attr(scaler, "min_", paths["scaler"]),
        "scaler_scale": _attr(scaler, "scale_", paths["scaler"]),
    }
    # Mirror FastICA.inverse_transform of the installed sklearn: `if self.whiten: X += self.mean_`.
    # Old pickles (sklearn 1.1/1.2) hold whiten='warn' with _whiten='arbitrary-variance': truthy either way.
    ica_whiten = _json_flag(ica.whiten)
    if ica_whiten:
        arrays["ica_mean"] = _attr(ica, "mean_", paths["ica"])
    else:
        # Without whitening FastICA has no mean_ and adds nothing; zeros keep the file layout fixed.
        arrays["ica_mean"] = np.zeros(arrays["ica_mixing"].shape[0])
    flags = {
        "pca_whiten": bool(pca.whiten),
        "ica_whiten": ica_whiten,
        "ica_whiten_internal": _json_flag(getattr(ica, "_whiten", ica.whiten)),
        "scaler_feature_range": [float(v) for v in scaler.feature_range],
    }
    return arrays, flags


def check_count(n_check: Any) -> int:
    """`n_check` as an int, or a one-line error (bool and non-integers are refused)."""
    if isinstance(n_check, bool) or not isinstance(n_check, (int, np.integer)) or n_check < 1:
        raise MotorlabError(f"n_check must be a positive integer; got {n_check!r}.")
    return int(n_check)


def check_chain(sar: SAR, pca: Any, ica: Any, scaler: Any, what: str, n_check: int = 1000, seed: int = 0) -> float:
    """Compare ``sar.decode`` with scikit-learn's inverse chain on random synergy vectors.

    The vectors are uniform in the scaler's feature_range:
    ``pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))``.

    Args:
        sar: the motorlab SAR.
        pca, ica, scaler: the fitted scikit-learn estimators.
        what: names the thing checked in error messages, e.g. "the converted SAR for DIR".
        n_check: number of random vectors.
        seed: their seed.

    Returns:
        The largest absolute difference found.

    Raises:
        MotorlabError: the chain fails to run, has another shape, or disagrees
            beyond ``CHECK_ATOL + CHECK_RTOL * |expected|``.
    """
    import sklearn

    lo, hi = (float(v) for v in scaler.feature_range)
    z = np.random.default_rng(seed).uniform(lo, hi, size=(int(n_check), sar.n_synergies))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # old-pickle attribute warnings; the numbers are what we check
            expected = pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))
    except Exception as e:  # an estimator from another sklearn version may fail in its own way
        raise MotorlabError(f"scikit-learn {sklearn.__version__} cannot run the inverse chain of {what} "
                            f"({type(e).__name__}: {e}); nothing was written.") from None
    got = sar.decode(z)
    expected = np.asarray(expected, dtype=np.float64)
    if got.shape != expected.shape:
        raise MotorlabError(f"decode gives shape {got.shape} but scikit-learn gives {expected.shape} for {what}; "
                            "nothing was written.")
    err = np.abs(got - expected)
    max_err = float(err.max())
    if not np.all(err <= CHECK_ATOL + CHECK_RTOL * np.abs(expected)):
        raise MotorlabError(f"{what} disagrees with scikit-learn's inverse chain "
                            f"(max abs error {max_err:.3g} > {CHECK_ATOL}); nothing was written.")
    return max_err


def _synergy_model_meta(metadata: dict[str, Any], n: int, m: int, path: Path) -> dict[str, Any]:
    """What a SynergyModel's metadata.npz adds to the SAR's metadata, checked against the pickles' shape."""
    for key, actual in (("n_synergies", n), ("n_muscles", m)):
        if key in metadata and metadata[key] != actual:
            raise MotorlabError(f"{path} says {key} = {metadata[key]}, but the pickles hold {actual}; "
                                "the files come from different models: re-save them together.")
    # MyoSuite 3.0.0 bakes scaler_margin into the scaler's min_/scale_ and stores no margin; later
    # or hand-made folders may record it (and muscle names), which is worth keeping.
    margin = metadata.get("scaler_margin", metadata.get("margin"))
    names = metadata.get("muscle_names")
    return {
        "myosuite_metadata": metadata,
        "scaler_margin": margin,
        "scaler_margin_source": ("metadata.npz" if margin is not None
                                 else "not recorded: already folded into the scaler's min_ and scale_"),
        "muscle_names": names,
        "source_clips": metadata.get("source_clips", []),
        "source_env": metadata.get("source_env"),
    }


# ------------------------------------------------------------------ import


def import_sklearn(folder: Path | str, trust: bool, out: Path | str, n_check: int = 1000, seed: int = 0) -> SAR:
    """Convert a published scikit-learn SAR folder (either MyoSuite layout) to a plain SAR file.

    The layout is detected (`detect_format`): the 2.x tutorial's ``pca.pkl``,
    ``ica.pkl``, ``normalizer.pkl``, or a MyoSuite 3.0 SynergyModel folder
    (``pca.pkl``, ``ica.pkl``, ``scaler.pkl``, ``metadata.npz``). Decoding mirrors
    the installed scikit-learn exactly:
    ``pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))``,
    honouring PCA ``whiten`` (scale by sqrt(explained_variance_)), FastICA
    ``whiten`` (``mean_`` is added back when it is truthy: True, 'warn' from old
    pickles, 'arbitrary-variance', 'unit-variance') and the scaler's
    feature_range and margin (both are in its min_ / scale_).

    Args:
        folder: folder holding the joblib pickles (and metadata.npz for 3.0).
        trust: must be True: unpickling runs arbitrary code from the files.
        out: the .npz file to write (an existing folder means ``out/sar.npz``).
        n_check: random synergy vectors (uniform in the scaler's feature_range)
            on which motorlab's decode must match scikit-learn's chain.
        seed: seed of those check vectors.

    Returns:
        The imported `SAR` (method "sklearn-import"); metadata holds
        ``import_format``, ``import_check_max_abs_error``, the pickles' sklearn
        version(s), and for 3.0 folders the metadata.npz entries
        (``myosuite_metadata``, ``scaler_margin``, ``muscle_names``, ``source_clips``).

    Raises:
        MotorlabError: folder or a file missing, trust not given, a pickle of
            the wrong type or shape, or decode disagreeing with scikit-learn
            (nothing is written then).
    """
    folder = Path(folder)
    fmt = detect_format(folder)
    if trust is not True:
        raise MotorlabError(
            f"importing {folder} means unpickling it, and unpickling runs arbitrary code from the files. "
            "Do it only for files from a source you trust, and then pass --trust."
        )
    n_check = check_count(n_check)
    out = Path(out)
    if out.is_dir():
        out = out / "sar.npz"

    sklearn = require_sklearn()
    from sklearn.decomposition import PCA, FastICA
    from sklearn.preprocessing import MinMaxScaler

    pca_file, ica_file, scaler_file = FORMATS[fmt][:3]
    paths = {"pca": folder / pca_file, "ica": folder / ica_file, "scaler": folder / scaler_file}
    versions: set[str] = set()
    pca = _load_pickle(paths["pca"], PCA, versions)
    ica = _load_pickle(paths["ica"], FastICA, versions)
    scaler = _load_pickle(paths["scaler"], MinMaxScaler, versions)
    arrays, flags = _chain_arrays(pca, ica, scaler, paths)
    meta: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "method": "sklearn-import",
        **flags,
        "vaf": (float(np.sum(pca.explained_variance_ratio_)) if hasattr(pca, "explained_variance_ratio_")
                else None),
        "vaf_definition": "sum of the PCA's explained_variance_ratio_ (as pickled)",
        "source_env": None,
        "import_format": fmt,
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
    n, m = int(weight.shape[0]), int(weight.shape[1])
    meta["n_synergies"], meta["n_muscles"] = n, m
    if fmt == SYNERGY_MODEL:
        meta.update(_synergy_model_meta(read_synergy_metadata(folder / "metadata.npz", trust), n, m,
                                        folder / "metadata.npz"))
    sar = SAR(method="sklearn-import", arrays=arrays, weight=weight, bias=bias, metadata=meta)
    # Verify against scikit-learn's own chain before anything is written.
    max_err = check_chain(sar, pca, ica, scaler, f"the converted SAR for {folder}", n_check, seed)
    sar = SAR(method="sklearn-import", arrays=arrays, weight=weight, bias=bias,
              metadata={**meta, "import_check_max_abs_error": max_err, "import_check_n": int(n_check)})
    save_sar(sar, out)
    return sar
