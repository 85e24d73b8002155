"""Write a motorlab SAR as a MyoSuite 3.0 ``SynergyModel`` folder (the reverse of `sklearn_import`).

MyoSuite 3.0 decodes synergies with fitted scikit-learn estimators,
``pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))``,
saved by ``myosuite.integrations.musclemimic.sar_extraction.save_synergy_model``
as ``pca.pkl``, ``ica.pkl``, ``scaler.pkl`` (joblib) and ``metadata.npz``.
This module builds those estimators from a SAR's plain arrays (no refit: the
attributes their transforms use are set directly), writes the folder with
MyoSuite's own writer, reads it back with MyoSuite's own reader and checks that
chain against motorlab's decode before the folder appears under its name.

The scaler keeps the SAR's synergy range (motorlab fits use [-1, 1]; MyoSuite's
own ``extract_synergies`` uses [0, 1]), so both decode the same z the same way.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.extras import install_hint, require
from motorlab.runs import current_umask
from motorlab.synergies.sar import SAR, load_sar, require_sklearn
from motorlab.synergies.sklearn_import import FORMATS, SYNERGY_MODEL, check_chain, check_count

# sklearn's own names for the two whitening variants; True / 'warn' (old pickles) meant the second.
_ICA_WHITEN = ("unit-variance", "arbitrary-variance")


@dataclass(frozen=True)
class ExportResult:
    """What `export_sklearn` wrote.

    Attributes:
        out: the SynergyModel folder.
        n_synergies, n_muscles: the SAR's shape.
        max_abs_error: largest |MyoSuite chain - motorlab decode| on the check vectors.
        n_check: number of check vectors.
    """

    out: Path
    n_synergies: int
    n_muscles: int
    max_abs_error: float
    n_check: int


def _set(estimator: Any, **attributes: Any) -> Any:
    for name, value in attributes.items():
        setattr(estimator, name, value)
    return estimator


def _ica_whiten(meta: dict[str, Any]) -> bool | str:
    """The FastICA ``whiten`` parameter that gives the SAR's inverse: False adds no mean back."""
    if not meta.get("ica_whiten"):
        return False
    for value in (meta.get("ica_whiten"), meta.get("ica_whiten_internal")):
        if value in _ICA_WHITEN:
            return value
    return "arbitrary-variance"


def _vaf(meta: dict[str, Any]) -> float | None:
    """The SAR's VAF as a fraction, or None when it is not recorded."""
    try:
        vaf = meta["vaf"]
    except KeyError:
        return None
    if isinstance(vaf, (int, float)) and not isinstance(vaf, bool) and math.isfinite(vaf) and 0 < vaf <= 1:
        return float(vaf)
    return None


def _pca(sar: SAR) -> Any:
    """A fitted-looking PCA: components_, mean_, explained_variance_ (and the ratios when the VAF is known)."""
    from sklearn.decomposition import PCA

    arr, meta = sar.arrays, sar.metadata
    comps, ev = arr["pca_components"].copy(), arr["pca_explained_variance"].copy()
    p, m = comps.shape
    pca = _set(PCA(n_components=p, whiten=bool(meta.get("pca_whiten")), svd_solver="full"),
               components_=comps, mean_=arr["pca_mean"].copy(), explained_variance_=ev,
               n_components_=p, n_features_in_=m)
    vaf = _vaf(meta)
    if vaf is not None:
        # VAF = sum(ev) / total variance, so the total, each ratio and the noise variance follow exactly.
        total = float(ev.sum()) / vaf
        _set(pca, explained_variance_ratio_=ev / total,
             noise_variance_=max(total - float(ev.sum()), 0.0) / (m - p) if m > p else 0.0)
    n_samples = meta.get("n_samples")
    if isinstance(n_samples, int) and n_samples > 1:
        _set(pca, n_samples_=n_samples, singular_values_=np.sqrt(ev * (n_samples - 1)))
    return pca


def _ica(sar: SAR) -> Any:
    """FastICA with mixing_, components_, mean_; a "pca" SAR gets the identity (no ICA step)."""
    from sklearn.decomposition import FastICA

    arr, n = sar.arrays, sar.n_synergies
    if sar.method == "pca":
        eye = np.eye(n)
        # MyoSuite's torch decode adds ica.mean_ whatever whiten says, so it is there (zeros).
        return _set(FastICA(n_components=n, whiten=False), components_=eye, mixing_=eye.copy(),
                    mean_=np.zeros(n), n_features_in_=n)
    mixing = arr["ica_mixing"].copy()
    return _set(FastICA(n_components=n, whiten=_ica_whiten(sar.metadata)), components_=arr["ica_components"].copy(),
                mixing_=mixing, mean_=arr["ica_mean"].copy(), n_features_in_=mixing.shape[0])


def _scaler(sar: SAR) -> Any:
    """MinMaxScaler with min_, scale_ and the data_min_/max_/range_ they imply for its feature_range."""
    from sklearn.preprocessing import MinMaxScaler

    arr, meta = sar.arrays, sar.metadata
    lo, hi = (float(v) for v in meta.get("scaler_feature_range", (-1.0, 1.0)))  # motorlab's fits: [-1, 1]
    min_, scale = arr["scaler_min"].copy(), arr["scaler_scale"].copy()
    data_min, data_max = (lo - min_) / scale, (hi - min_) / scale
    scaler = _set(MinMaxScaler(feature_range=(lo, hi)), min_=min_, scale_=scale, data_min_=data_min,
                  data_max_=data_max, data_range_=data_max - data_min, n_features_in_=sar.n_synergies)
    if isinstance(meta.get("n_samples"), int):
        scaler.n_samples_seen_ = meta["n_samples"]
    return scaler


def estimators_from_sar(sar: SAR) -> tuple[Any, Any, Any]:
    """scikit-learn PCA, FastICA and MinMaxScaler whose inverse chain is ``sar.decode``.

    Args:
        sar: a SAR of method "pca-ica", "sklearn-import" or "pca" (the ICA step is then the identity).

    Returns:
        (pca, ica, scaler), usable with transform and inverse_transform.

    Raises:
        MotorlabError: an "nmf" SAR (NMF components are no PCA basis, so the
            chain could decode it but not encode activations into it).
    """
    if sar.method == "nmf":
        raise MotorlabError("an nmf SAR cannot be written as MyoSuite's PCA -> FastICA -> MinMaxScaler chain "
                            "(NMF components are not a PCA basis); fit one with --method pca-ica (or pca) to export.")
    require_sklearn()
    return _pca(sar), _ica(sar), _scaler(sar)


def _check_out(out: Path) -> None:
    if out.is_dir() and any(out.iterdir()):
        raise MotorlabError(f"--out {out} already exists and is not empty; pass a new folder "
                            "(export-sklearn never overwrites).")
    if out.exists() and not out.is_dir():
        raise MotorlabError(f"--out {out} is a file; pass a new folder for the SynergyModel files.")


def export_sklearn(sar: SAR | Path | str, out: Path | str, n_check: int = 1000, seed: int = 0) -> ExportResult:
    """Write `sar` as a MyoSuite 3.0 SynergyModel folder, atomically.

    The folder is written beside `out` under a temp name by MyoSuite's
    ``save_synergy_model``, read back by ``load_synergy_model``, its inverse
    chain checked against ``sar.decode`` on `n_check` random synergy vectors,
    and only then renamed to `out`; on any failure nothing is left behind.

    Args:
        sar: a `SAR` or the path of a sar.npz.
        out: the folder to create (it may exist only as an empty folder).
        n_check: random synergy vectors (uniform in the scaler's range) for the check.
        seed: seed of those vectors.

    Returns:
        An `ExportResult` with the measured max abs decode difference.

    Raises:
        MotorlabError: `out` exists and is not empty, the SAR cannot be read or
            is an nmf SAR, MyoSuite or scikit-learn is not installed, or
            MyoSuite's chain disagrees with motorlab's decode.
    """
    out = Path(out)
    _check_out(out)
    if not isinstance(sar, SAR):
        sar = load_sar(sar)
    n_check = check_count(n_check)
    pca, ica, scaler = estimators_from_sar(sar)
    myo = require("myosuite.integrations.musclemimic.sar_extraction", "myosuite",
                  "export-sklearn writes MyoSuite's SynergyModel format and needs MyoSuite")
    vaf = _vaf(sar.metadata)
    model = myo.SynergyModel(pca=pca, ica=ica, scaler=scaler, n_synergies=sar.n_synergies,
                             n_muscles=sar.n_muscles, vaf=math.nan if vaf is None else vaf,
                             source_clips=[str(c) for c in sar.metadata.get("source_clips") or []])
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp"))
    except OSError as e:
        raise MotorlabError(f"cannot write beside {out} ({e.strerror}); pass an --out in a folder you can write.") \
            from None
    try:
        myo.save_synergy_model(model, tmp)
        written = sorted(p.name for p in tmp.iterdir())
        if written != sorted(FORMATS[SYNERGY_MODEL]):  # MyoSuite changed its layout under us
            raise MotorlabError(f"MyoSuite's save_synergy_model wrote {', '.join(written)}, not the 3.0 layout "
                                f"{', '.join(FORMATS[SYNERGY_MODEL])}; {install_hint('myosuite')}.")
        loaded = myo.load_synergy_model(tmp)  # our own files, just written
        err = check_chain(sar, loaded.pca, loaded.ica, loaded.scaler, f"the SynergyModel exported to {out}",
                          n_check, seed)
        os.chmod(tmp, 0o777 & ~current_umask())  # mkdtemp's 0700 would hide the folder from others
        try:
            os.replace(tmp, out)  # an empty `out` folder is replaced; _check_out refused anything else
        except OSError as e:  # something appeared at `out` meanwhile
            raise MotorlabError(f"cannot create {out} ({e.strerror}); pass a new folder as --out.") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return ExportResult(out=out, n_synergies=sar.n_synergies, n_muscles=sar.n_muscles, max_abs_error=err,
                        n_check=n_check)

