"""Synergistic Action Representation (SAR): fit, VAF, save/load, decode.

Muscle activations recorded from good rollouts, shape (n_samples, n_muscles)
with values in [0, 1], are reduced to N synergies (Berg et al. 2023, MyoSuite).
The same works for any motor signal in a box (a robot's actuator controls, an
env's actions): "muscles" below stands for the signal's elements, and the SAR's
metadata records which signal it decodes to and its bounds (`signal_of`).

- ``pca-ica``: PCA (N components) -> FastICA -> MinMaxScaler to [-1, 1]
- ``pca``: PCA (N components) -> MinMaxScaler to [-1, 1]
- ``nmf``: NMF coefficients (N) -> MinMaxScaler to [-1, 1]
- ``sklearn-import``: a PCA -> FastICA -> MinMaxScaler chain converted from
  third-party pickles (see `motorlab.synergies.sklearn_import`).

An agent acts with z in [-1, 1]^N. Every inverse in these chains is affine, so
decoding to muscle space is ONE affine map ``decode(z) = z @ weight + bias``,
composed once from the plain fitted arrays (`affine_from_arrays`) and applied
as a single batched matrix product.

`sar.npz` holds only plain arrays plus a JSON metadata string, so loading it
never unpickles anything. scikit-learn is needed to *fit*, not to decode or load.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.runs import atomic_write_npz

METHODS = ("pca-ica", "pca", "nmf", "sklearn-import")
FIT_METHODS = ("pca-ica", "pca", "nmf")
FORMAT_VERSION = 1

# Plain arrays each method needs (npz keys). pca-ica and sklearn-import share one chain.
_PCA_KEYS = ("pca_mean", "pca_components", "pca_explained_variance")
_ICA_KEYS = ("ica_mixing", "ica_mean", "ica_components")
_SCALER_KEYS = ("scaler_min", "scaler_scale")
REQUIRED_ARRAYS: dict[str, tuple[str, ...]] = {
    "pca-ica": _PCA_KEYS + _ICA_KEYS + _SCALER_KEYS,
    "sklearn-import": _PCA_KEYS + _ICA_KEYS + _SCALER_KEYS,
    "pca": _PCA_KEYS + _SCALER_KEYS,
    "nmf": ("nmf_components",) + _SCALER_KEYS,
}
_DECODE_KEYS = ("decode_weight", "decode_bias")
_META_KEY = "metadata"

# Fit settings: fixed so that a fit is reproducible from (activations, seed).
ICA_MAX_ITER = 1000
NMF_MAX_ITER = 2000
NMF_INIT = "nndsvda"


class SarFormatError(ValueError):
    """Plain arrays / metadata that do not describe a valid SAR (callers add context)."""


# --------------------------------------------------------------------------- model


@dataclass(frozen=True, eq=False)
class SAR:
    """A fitted synergy model: plain arrays plus the affine decode map they imply.

    Attributes:
        method: "pca-ica", "pca", "nmf" or "sklearn-import".
        arrays: the plain fitted arrays (keys as in `REQUIRED_ARRAYS[method]`).
        weight: (n_synergies, n_muscles) float64 decode weight.
        bias: (n_muscles,) float64 decode bias.
        metadata: JSON-able dict (method, n_synergies, n_muscles, vaf, source_env,
            created, versions, and the method's flags such as pca_whiten).
    """

    method: str
    arrays: dict[str, np.ndarray]
    weight: np.ndarray
    bias: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:  # the sizes, not every array (a notebook cell ending in `sar` prints this)
        return f"SAR({self.method}, {self.n_synergies} synergies x {self.n_muscles} muscles)"

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise MotorlabError(f"unknown SAR method {self.method!r}; expected one of {', '.join(METHODS)}.")
        weight = np.ascontiguousarray(self.weight, dtype=np.float64)
        bias = np.ascontiguousarray(self.bias, dtype=np.float64)
        if weight.ndim != 2 or bias.shape != (weight.shape[1],):
            raise MotorlabError(
                f"SAR decode weight must be (n_synergies, n_muscles) and bias (n_muscles,); "
                f"got {weight.shape} and {bias.shape}."
            )
        # Read-only: a frozen model must not change under an agent that holds it.
        weight.flags.writeable = False
        bias.flags.writeable = False
        arrays = {}
        for k, v in self.arrays.items():
            a = np.array(v, dtype=np.float64)
            a.flags.writeable = False
            arrays[k] = a
        object.__setattr__(self, "weight", weight)
        object.__setattr__(self, "bias", bias)
        object.__setattr__(self, "arrays", arrays)
        # Cached so decode's shape check is one tuple comparison.
        object.__setattr__(self, "_in_shape", (weight.shape[0],))

    @property
    def n_synergies(self) -> int:
        """Size of the synergy (action) space."""
        return int(self.weight.shape[0])

    @property
    def n_muscles(self) -> int:
        """Number of muscles decoded to."""
        return int(self.weight.shape[1])

    def decode(self, z: Any) -> np.ndarray:
        """Map synergy actions to muscle activations: ``z @ weight + bias``.

        Args:
            z: array-like of shape (..., n_synergies); any leading batch shape.

        Returns:
            float64 array of shape (..., n_muscles). Not clipped: callers clip to
            the muscle range if they need to.

        Raises:
            MotorlabError: the last dimension of z is not n_synergies.
        """
        z = np.asarray(z, dtype=np.float64)  # no copy when already float64
        if z.shape[-1:] != self._in_shape:  # type: ignore[attr-defined]
            raise MotorlabError(
                f"synergy action has shape {z.shape}, but this SAR has {self.weight.shape[0]} synergies "
                f"(decoding to {self.weight.shape[1]} muscles); pass an array whose last dimension is "
                f"{self.weight.shape[0]}."
            )
        # np.dot has less call overhead than `@` for 1-D/2-D (the per-step case); `@` stays
        # BLAS-backed for stacked batches, where np.dot falls back to a slow loop.
        out = np.dot(z, self.weight) if z.ndim <= 2 else z @ self.weight
        out += self.bias
        return out

    def encode(self, activations: Any) -> np.ndarray:
        """Forward transform: muscle activations to synergy coordinates.

        For PCA-based methods this is the exact forward chain (projection, so
        ``decode(encode(a))`` is the rank-N reconstruction of `a`). For nmf the
        coefficients are the non-negative least-squares fit per sample (scipy
        NNLS, a Python loop: meant for inspection and tests, not for control).

        Args:
            activations: array-like of shape (..., n_muscles).

        Returns:
            float64 array of shape (..., n_synergies).

        Raises:
            MotorlabError: the last dimension is not n_muscles.
        """
        a = np.asarray(activations, dtype=np.float64)
        if a.shape[-1:] != (self.n_muscles,):
            raise MotorlabError(
                f"activations have shape {a.shape}, but this SAR decodes to {self.n_muscles} muscles; "
                f"pass an array whose last dimension is {self.n_muscles}."
            )
        arr, meta = self.arrays, self.metadata
        if self.method == "nmf":
            from scipy.optimize import nnls

            comps = arr["nmf_components"]
            flat = a.reshape(-1, self.n_muscles)
            coef = np.array([nnls(comps.T, row)[0] for row in flat]).reshape(*a.shape[:-1], comps.shape[0])
            return coef * arr["scaler_scale"] + arr["scaler_min"]
        x = (a - arr["pca_mean"]) @ arr["pca_components"].T
        if meta.get("pca_whiten"):
            x = x / np.sqrt(arr["pca_explained_variance"])
        if self.method in ("pca-ica", "sklearn-import"):
            if meta.get("ica_whiten"):  # sklearn: `if self.whiten: X -= mean_`
                x = x - arr["ica_mean"]
            x = x @ arr["ica_components"].T
        return x * arr["scaler_scale"] + arr["scaler_min"]


# ------------------------------------------------------------------ affine map


def _check_arrays(method: str, arrays: dict[str, np.ndarray]) -> tuple[int, int]:
    """Check that the method's arrays are present, finite and of consistent shapes.

    Returns:
        (n_synergies, n_muscles).

    Raises:
        SarFormatError: naming the first problem found.
    """
    if method not in REQUIRED_ARRAYS:
        raise SarFormatError(f"unknown SAR method {method!r} (expected one of {', '.join(METHODS)})")
    missing = [k for k in REQUIRED_ARRAYS[method] if k not in arrays]
    if missing:
        raise SarFormatError(f"missing array(s) {', '.join(missing)} for method {method!r}")
    for k in REQUIRED_ARRAYS[method]:
        a = arrays[k]
        if a.dtype.kind not in "fiu":
            raise SarFormatError(f"array {k} has dtype {a.dtype}, expected floating point")
        if not np.all(np.isfinite(a)):
            raise SarFormatError(f"array {k} holds non-finite values (NaN or Inf)")

    def shape(k: str, expected: tuple[int, ...]) -> None:
        if arrays[k].shape != expected:
            raise SarFormatError(f"array {k} has shape {arrays[k].shape}, expected {expected}")

    if arrays["scaler_min"].ndim != 1:
        raise SarFormatError(f"array scaler_min has shape {arrays['scaler_min'].shape}, expected 1-D")
    n = arrays["scaler_min"].shape[0]
    shape("scaler_scale", (n,))
    if np.any(arrays["scaler_scale"] == 0):
        raise SarFormatError("array scaler_scale holds zeros (a min-max scale is never zero)")
    if method == "nmf":
        comps = arrays["nmf_components"]
        if comps.ndim != 2 or comps.shape[0] != n:
            raise SarFormatError(f"array nmf_components has shape {comps.shape}, expected ({n}, n_muscles)")
        return n, comps.shape[1]
    comps = arrays["pca_components"]
    if comps.ndim != 2:
        raise SarFormatError(f"array pca_components has shape {comps.shape}, expected (n_components, n_muscles)")
    p, m = comps.shape
    shape("pca_mean", (m,))
    shape("pca_explained_variance", (p,))
    if method == "pca":
        if p != n:
            raise SarFormatError(f"array pca_components has {p} rows but the scaler has {n} features")
        return n, m
    # FastICA maps the p PCA scores to n sources; sklearn's mixing_ is (p, n).
    shape("ica_mixing", (p, n))
    shape("ica_components", (n, p))
    shape("ica_mean", (p,))
    return n, m


def affine_from_arrays(method: str, arrays: dict[str, np.ndarray],
                        metadata: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Compose the decode map ``z @ W + b`` from the plain fitted arrays.

    Mirrors scikit-learn's inverse transforms exactly:
    MinMaxScaler ``(X - min_) / scale_``; FastICA ``X @ mixing_.T (+ mean_ if whiten)``;
    PCA ``X (* sqrt(explained_variance_) if whiten) @ components_ + mean_``.

    Args:
        method: one of `METHODS`.
        arrays: the method's plain arrays.
        metadata: holds "pca_whiten" / "ica_whiten" for PCA/ICA methods.

    Returns:
        (weight (N, M), bias (M,)), float64.

    Raises:
        SarFormatError: missing, non-finite or inconsistent arrays.
    """
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    _check_arrays(method, arrays)
    arrays = {k: arrays[k].astype(np.float64, copy=False) for k in REQUIRED_ARRAYS[method]}
    # Scaler inverse as z * d + c with a diagonal d.
    d = 1.0 / arrays["scaler_scale"]
    c = -arrays["scaler_min"] * d
    if method == "nmf":
        comps = arrays["nmf_components"]
        return d[:, None] * comps, c @ comps
    pca = arrays["pca_components"]
    if metadata.get("pca_whiten"):
        pca = np.sqrt(arrays["pca_explained_variance"])[:, None] * pca
    if method == "pca":
        return d[:, None] * pca, c @ pca + arrays["pca_mean"]
    mix_t = arrays["ica_mixing"].T  # (n, p)
    ica_w = d[:, None] * mix_t
    ica_b = c @ mix_t
    # sklearn adds mean_ when `self.whiten` is truthy (True, 'warn', '...-variance').
    if metadata.get("ica_whiten"):
        ica_b = ica_b + arrays["ica_mean"]
    return ica_w @ pca, ica_b @ pca + arrays["pca_mean"]


# ------------------------------------------------------------------ validation


def _validate_activations(activations: Any) -> np.ndarray:
    try:
        x = np.array(activations, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise MotorlabError(f"activations must be a numeric array of shape (n_samples, n_muscles) ({e}).") from None
    if x.ndim != 2:
        raise MotorlabError(
            f"activations must be 2-D (n_samples, n_muscles); got shape {x.shape}. "
            "Stack the recorded steps row by row."
        )
    if x.shape[0] < 2 or x.shape[1] < 1:
        raise MotorlabError(f"activations need at least 2 samples and 1 muscle; got shape {x.shape}.")
    bad = ~np.isfinite(x)
    if bad.any():
        rows = np.unique(np.nonzero(bad)[0])
        raise MotorlabError(
            f"activations hold {int(bad.sum())} non-finite values (NaN or Inf), in {len(rows)} rows "
            f"(first: row {int(rows[0])}); drop those samples before fitting."
        )
    return x


def _validate_method(method: str, allowed: tuple[str, ...]) -> str:
    if method not in allowed:
        raise MotorlabError(f"unknown synergy method {method!r}; choose one of {', '.join(allowed)}.")
    return method


def require_sklearn():
    try:
        import sklearn
    except ImportError:
        raise MotorlabError(
            "fitting synergies needs scikit-learn; install it with `pip install scikit-learn`."
        ) from None
    return sklearn


def library_versions() -> dict[str, str | None]:
    from importlib import metadata  # the installed version, as provenance reads it (not motorlab, the façade above)

    try:
        import sklearn

        skl = sklearn.__version__
    except ImportError:
        skl = None
    return {"numpy": np.__version__, "sklearn": skl, "motorlab": metadata.version("motorlab")}


def utc_now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


# ------------------------------------------------------------------ VAF


def _pca_vaf(x: np.ndarray) -> np.ndarray:
    """Cumulative explained-variance ratio for N = 1..n_muscles."""
    centered = x - x.mean(axis=0)
    s = np.linalg.svd(centered, compute_uv=False)
    energy = np.cumsum(s * s)
    if energy[-1] <= 0:
        raise MotorlabError("activations have zero variance (every sample is the same); record varied rollouts.")
    # Dividing by the last cumulative sum makes the curve end at exactly 1.0 and stay <= 1.
    vaf = energy / energy[-1]
    # More muscles than samples: the rank is below n_muscles and the curve is already 1.
    return np.concatenate([vaf, np.ones(x.shape[1] - vaf.shape[0])])


def _fit_nmf(x: np.ndarray, n: int, seed: int):
    """Fit sklearn NMF; returns (model, coefficients, uncentered VAF)."""
    from sklearn.decomposition import NMF
    from sklearn.exceptions import ConvergenceWarning

    model = NMF(n_components=n, init=NMF_INIT, max_iter=NMF_MAX_ITER, random_state=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)  # recorded in metadata instead
        coef = model.fit_transform(x)
    resid = x - coef @ model.components_
    vaf = 1.0 - float(np.sum(resid * resid)) / float(np.sum(x * x))
    return model, coef, vaf


def check_nmf_input(x: np.ndarray) -> None:
    if x.min() < 0:
        raise MotorlabError(
            f"method 'nmf' needs non-negative activations; the smallest value is {x.min():.4g}. "
            "Use method 'pca-ica' (any signal, e.g. a robot's controls in [-1, 1]) or clip the activations to [0, 1]."
        )
    if not np.any(x):
        raise MotorlabError("activations are all zero; record rollouts where muscles are active.")


def vaf_curve(activations: Any, method: str = "pca", max_n: int | None = None, seed: int = 0) -> np.ndarray:
    """Variance accounted for by N synergies, for N = 1..max_n.

    - pca / pca-ica: ``1 - ||X - X_hat_N||^2 / ||X - mean||^2``, the cumulative
      explained-variance ratio (ICA is an invertible map inside the PCA subspace,
      so it does not change the reconstruction). Monotone non-decreasing, <= 1,
      and exactly 1 at N = n_muscles.
    - nmf: the classic muscle-synergy VAF ``1 - ||X - W H||^2 / ||X||^2``
      (uncentered), one NMF fit per N. NMF is a non-convex local fit, so this
      curve is usually but not guaranteed to be monotone.

    Args:
        activations: (n_samples, n_muscles) array.
        method: "pca", "pca-ica" or "nmf".
        max_n: largest N (default n_muscles; use it to save NMF fits).
        seed: NMF random_state.

    Returns:
        float64 array of length max_n; entry i is the VAF of N = i + 1.

    Raises:
        MotorlabError: bad activations, method or max_n.
    """
    x = _validate_activations(activations)
    _validate_method(method, FIT_METHODS)
    m = x.shape[1]
    if max_n is None:
        max_n = m
    if isinstance(max_n, bool) or not isinstance(max_n, (int, np.integer)) or not 1 <= max_n <= m:
        raise MotorlabError(f"max_n must be an integer in [1, {m}] (the number of muscles); got {max_n!r}.")
    if method == "nmf":
        require_sklearn()
        check_nmf_input(x)
        return np.array([_fit_nmf(x, n, seed)[2] for n in range(1, int(max_n) + 1)])
    return _pca_vaf(x)[: int(max_n)]


def smallest_n(vaf_values: Any, threshold: float) -> int:
    """The smallest N whose VAF reaches `threshold`.

    Args:
        vaf_values: VAF for N = 1, 2, ... (as from `vaf_curve`).
        threshold: in (0, 1]; met when VAF >= threshold - 1e-12 (float rounding).

    Returns:
        N (1-based).

    Raises:
        MotorlabError: threshold outside (0, 1], or no N reaches it.
    """
    _validate_threshold(threshold)
    values = np.asarray(vaf_values, dtype=np.float64).ravel()
    # A 1e-12 slack so that e.g. --vaf 1.0 is met where the curve is 1 up to rounding.
    hits = np.nonzero(values >= threshold - 1e-12)[0]
    if hits.size == 0:
        best = float(np.max(values)) if values.size else float("nan")
        raise MotorlabError(
            f"no number of synergies up to {values.size} reaches VAF {threshold} (best: {best:.6f}); "
            "lower the --vaf threshold or pass --n-synergies."
        )
    return int(hits[0]) + 1


def _validate_threshold(threshold: Any) -> float:
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.floating, np.integer)) \
            or not math.isfinite(float(threshold)) or not 0 < float(threshold) <= 1:
        raise MotorlabError(f"--vaf must be a fraction in (0, 1], e.g. 0.95; got {threshold!r}.")
    return float(threshold)


# ------------------------------------------------------------------ fit


def fit_sar(
    activations: Any,
    n_synergies: int | None = None,
    vaf: float | None = None,
    method: str = "pca-ica",
    seed: int = 0,
    source_env: str | None = None,
    signal: str | None = None,
    bounds: tuple[Any, Any] | None = None,
    names: list[str] | None = None,
) -> SAR:
    """Fit a synergy model to recorded muscle activations (or another motor signal).

    Args:
        activations: (n_samples, n_muscles) array, values normally in [0, 1].
        n_synergies: number of synergies N; exactly one of n_synergies / vaf.
        vaf: VAF threshold in (0, 1]: use the smallest N whose VAF (by the
            method's definition, see `vaf_curve`) reaches it.
        method: "pca-ica" (PCA -> FastICA -> MinMaxScaler), "pca" or "nmf".
        seed: random_state of FastICA / NMF.
        source_env: env id the activations came from (metadata only).
        signal: what the activations are ("act", "ctrl", "action"; metadata, read by
            `SynergyActionWrapper`); None for muscle activations of unknown origin.
        bounds: the signal's per-element (low, high), +-inf where unbounded (metadata).
        names: each muscle's (signal element's) name, e.g. the MuJoCo actuator's (metadata
            `names`: heatmaps label rows with them, `synergies compare` matches on them).

    Returns:
        The fitted `SAR`; metadata["vaf"] is the VAF the chosen N achieves.

    Raises:
        MotorlabError: bad activations, method, N or threshold.
    """
    x = _validate_activations(activations)
    _validate_method(method, FIT_METHODS)
    n_samples, m = x.shape
    if (n_synergies is None) == (vaf is None):
        raise MotorlabError("give exactly one of --n-synergies or --vaf (a VAF threshold such as 0.95).")
    require_sklearn()
    from sklearn.preprocessing import MinMaxScaler

    limit = min(m, n_samples)
    if method == "nmf":
        check_nmf_input(x)
    if n_synergies is not None:
        if isinstance(n_synergies, bool) or not isinstance(n_synergies, (int, np.integer)) \
                or not 1 <= n_synergies <= m:
            raise MotorlabError(
                f"n_synergies must be an integer in [1, {m}] (the number of muscles); got {n_synergies!r}."
            )
        if n_synergies > n_samples:
            raise MotorlabError(
                f"n_synergies={n_synergies} exceeds the {n_samples} samples recorded; record more rollouts."
            )
        n = int(n_synergies)
        curve = None
    else:
        threshold = _validate_threshold(vaf)
        if method == "nmf":
            # Fit N = 1, 2, ... and stop at the first that reaches the threshold.
            curve = []
            for k in range(1, limit + 1):
                curve.append(_fit_nmf(x, k, seed)[2])
                if curve[-1] >= threshold:
                    break
            n = smallest_n(curve, threshold)
        else:
            curve = _pca_vaf(x)[:limit]
            n = smallest_n(curve, threshold)

    meta: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "method": method,
        "n_synergies": n,
        "n_muscles": m,
        "n_samples": n_samples,
        "vaf": None,
        "vaf_threshold": None if vaf is None else float(vaf),
        "vaf_definition": ("1 - |X - WH|^2 / |X|^2 (uncentered)" if method == "nmf"
                           else "1 - |X - X_hat|^2 / |X - mean|^2"),
        "source_env": source_env,
        "seed": int(seed),
        "scaler_feature_range": [-1.0, 1.0],
        "created": utc_now(),
        "versions": library_versions(),
        **_signal_metadata(signal, bounds, m),
        **({"names": [str(x) for x in names]} if names is not None and len(names) == m else {}),
    }
    scaler = MinMaxScaler(feature_range=(-1, 1))
    arrays: dict[str, np.ndarray] = {}
    if method == "nmf":
        model, coef, achieved = _fit_nmf(x, n, seed)
        scaler.fit(coef)
        arrays["nmf_components"] = model.components_
        meta.update(vaf=achieved, nmf_init=NMF_INIT, nmf_n_iter=int(model.n_iter_),
                    nmf_converged=bool(model.n_iter_ < NMF_MAX_ITER))
    else:
        from sklearn.decomposition import PCA

        pca = PCA(n_components=n, svd_solver="full")
        scores = pca.fit_transform(x)
        arrays.update(pca_mean=pca.mean_, pca_components=pca.components_,
                      pca_explained_variance=pca.explained_variance_)
        meta.update(vaf=float(_pca_vaf(x)[n - 1]) if curve is None else float(curve[n - 1]), pca_whiten=False)
        if method == "pca-ica":
            from sklearn.decomposition import FastICA
            from sklearn.exceptions import ConvergenceWarning

            ev = pca.explained_variance_
            if ev[-1] <= 1e-12 * ev[0]:
                rank = int(np.sum(ev > 1e-12 * ev[0]))
                raise MotorlabError(
                    f"the activations span only {rank} independent directions, so ICA cannot separate "
                    f"{n} synergies; use n_synergies <= {rank} (or --vaf)."
                )
            # sklearn's FastICA whitening flips signs with `u *= sign(u[0])`. PCA scores are
            # already decorrelated, so u is axis-aligned and an exact 0 in u[0] wipes a whole
            # direction (singular mixing). A fixed random rotation of the scores avoids the
            # exact zeros; folding it back below keeps this a FastICA of the PCA scores.
            rot = np.linalg.qr(np.random.default_rng(seed).normal(size=(n, n)))[0]
            ica = FastICA(whiten="unit-variance", random_state=seed, max_iter=ICA_MAX_ITER)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)  # recorded in metadata instead
                scores = ica.fit_transform(scores @ rot)
            components = ica.components_ @ rot.T
            mixing = rot @ ica.mixing_
            if not np.allclose(components @ mixing, np.eye(n), atol=1e-6):
                raise MotorlabError(
                    f"FastICA found no invertible unmixing for {n} synergies; try fewer synergies or another --seed."
                )
            arrays.update(ica_mixing=mixing, ica_mean=ica.mean_ @ rot.T, ica_components=components)
            meta.update(ica_whiten="unit-variance", ica_n_iter=int(ica.n_iter_),
                        ica_converged=bool(ica.n_iter_ < ICA_MAX_ITER))
        scaler.fit(scores)
    arrays.update(scaler_min=scaler.min_, scaler_scale=scaler.scale_)
    arrays = {k: np.asarray(v, dtype=np.float64) for k, v in arrays.items()}
    weight, bias = affine_from_arrays(method, arrays, meta)
    return SAR(method=method, arrays=arrays, weight=weight, bias=bias, metadata=meta)


def _signal_metadata(signal: str | None, bounds: tuple[Any, Any] | None, m: int) -> dict[str, Any]:
    """metadata keys `signal`, `signal_low`, `signal_high` (JSON: None where unbounded)."""
    meta: dict[str, Any] = {} if signal is None else {"signal": str(signal)}
    if bounds is not None:
        low, high = (np.broadcast_to(np.asarray(b, dtype=np.float64), (m,)) for b in bounds)
        meta["signal_low"] = [float(v) if np.isfinite(v) else None for v in low]
        meta["signal_high"] = [float(v) if np.isfinite(v) else None for v in high]
    return meta


def signal_of(sar: SAR) -> tuple[str, np.ndarray | None, np.ndarray | None]:
    """What a SAR decodes to: ("act" | "ctrl" | "action", low, high). SARs fitted before signals
    existed, and imported ones, decode to muscle activations ("act"); bounds are None where
    the metadata has none, +-inf where an element is unbounded."""
    meta = sar.metadata

    def bound(key: str, inf: float) -> np.ndarray | None:
        values = meta.get(key)
        if not isinstance(values, list) or len(values) != sar.n_muscles:
            return None
        return np.array([inf if v is None else float(v) for v in values])

    return str(meta.get("signal") or "act"), bound("signal_low", -np.inf), bound("signal_high", np.inf)


# ------------------------------------------------------------------ save / load


def _json_default(value: Any) -> Any:
    if hasattr(value, "item") and getattr(value, "ndim", 1) == 0:
        return value.item()
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def save_sar(sar: SAR, path: Path | str) -> Path:
    """Write `sar` to ONE .npz file (plain arrays, no pickle), atomically.

    Keys: the method's plain arrays, ``decode_weight``, ``decode_bias`` and
    ``metadata`` (a JSON string in a 0-d unicode array). The file is written
    exactly at `path` (no suffix is added).

    Args:
        sar: the model.
        path: destination file.

    Returns:
        The path written.

    Raises:
        MotorlabError: `sar` is not a SAR, or `path` is a folder.
    """
    if not isinstance(sar, SAR):
        raise MotorlabError(f"save_sar needs a SAR, got {type(sar).__name__}.")
    path = Path(path)
    if path.is_dir():
        raise MotorlabError(f"{path} is a folder; pass a file path such as {path / 'sar.npz'}.")
    reserved = set(_DECODE_KEYS) | {_META_KEY}
    clash = reserved & set(sar.arrays)
    if clash:
        raise MotorlabError(f"SAR arrays may not be named {', '.join(sorted(clash))}.")
    meta = {**sar.metadata, "method": sar.method, "n_synergies": sar.n_synergies, "n_muscles": sar.n_muscles}
    meta.setdefault("format_version", FORMAT_VERSION)
    text = json.dumps(meta, default=_json_default, allow_nan=False, sort_keys=True)
    atomic_write_npz(path, **sar.arrays, decode_weight=sar.weight, decode_bias=sar.bias,
                     metadata=np.array(text, dtype=np.str_))
    return path


def load_sar(path: Path | str) -> SAR:
    """Read a SAR written by `save_sar`; never unpickles.

    The decode map is recomputed from the plain arrays and must match the
    stored ``decode_weight`` / ``decode_bias`` (a corruption check).

    Args:
        path: the .npz file.

    Returns:
        The `SAR`.

    Raises:
        MotorlabError: missing file, not an npz, missing keys, wrong shapes,
            non-finite values, bad metadata, or decode arrays that do not match.
    """
    path = Path(path)
    fix = "re-create it (fit the SAR again, or re-import its source pickles)."
    if not path.exists():
        raise MotorlabError(f"SAR file {path} does not exist; check the path or fit a SAR first.")
    if path.is_dir() and (path / "sar.npz").is_file():  # a `synergies fit` run folder
        path = path / "sar.npz"
    if not path.is_file():
        raise MotorlabError(f"{path} is not a file; pass the sar.npz file itself (or the folder of a synergies fit).")

    def bad(problem: str) -> MotorlabError:
        return MotorlabError(f"SAR file {path} is corrupt or not a SAR: {problem}; {fix}")

    try:
        npz = np.load(path, allow_pickle=False)
        if not isinstance(npz, np.lib.npyio.NpzFile):  # a single .npy array
            raise bad("it is a single .npy array, not an .npz archive")
        with npz:
            data = {k: npz[k] for k in npz.files}
    except MotorlabError:
        raise
    except Exception as e:  # parsing untrusted bytes: zipfile/zlib/npy-header errors of many types
        if isinstance(e, ValueError) and "pickle" in str(e):
            raise bad("it is not a plain .npz archive (reading it would need unpickling, which motorlab never does)") from None
        raise bad(f"cannot read it as an .npz archive ({type(e).__name__}: {e})") from None

    missing = [k for k in (*_DECODE_KEYS, _META_KEY) if k not in data]
    if missing:
        raise bad(f"missing key(s) {', '.join(missing)}")
    meta_arr = data.pop(_META_KEY)
    if meta_arr.ndim != 0 or meta_arr.dtype.kind != "U":
        raise bad("'metadata' is not a JSON string")
    try:
        meta = json.loads(str(meta_arr))
    except ValueError as e:
        raise bad(f"'metadata' is not valid JSON ({e})") from None
    if not isinstance(meta, dict):
        raise bad("'metadata' is not a JSON object")
    version = meta.get("format_version", FORMAT_VERSION)
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise bad(f"format_version {version!r} is newer than this motorlab reads ({FORMAT_VERSION}); upgrade motorlab")
    method = meta.get("method")
    if method not in REQUIRED_ARRAYS:
        raise bad(f"metadata method {method!r} is not one of {', '.join(METHODS)}")

    weight, bias = data.pop("decode_weight"), data.pop("decode_bias")
    try:
        n, m = _check_arrays(method, data)
        expected_w, expected_b = affine_from_arrays(method, data, meta)
    except SarFormatError as e:
        raise bad(str(e)) from None
    for name, arr, shape in (("decode_weight", weight, (n, m)), ("decode_bias", bias, (m,))):
        if arr.shape != shape:
            raise bad(f"{name} has shape {arr.shape}, expected {shape}")
        if arr.dtype.kind != "f" or not np.all(np.isfinite(arr)):
            raise bad(f"{name} is not a finite float array")
    if meta.get("n_synergies") != n or meta.get("n_muscles") != m:
        raise bad(f"metadata says {meta.get('n_synergies')} synergies x {meta.get('n_muscles')} muscles, "
                  f"the arrays hold {n} x {m}")
    # Tolerance covers BLAS differences between machines, not real edits.
    scale = max(1.0, float(np.max(np.abs(expected_w))), float(np.max(np.abs(expected_b))))
    err = max(float(np.max(np.abs(weight - expected_w))), float(np.max(np.abs(bias - expected_b))))
    if not err <= 1e-9 * scale:
        raise bad(f"the stored decode map differs from the one its arrays imply (max difference {err:.3g})")
    keep = {k: v for k, v in data.items() if k in REQUIRED_ARRAYS[method]}
    return SAR(method=method, arrays=keep, weight=weight, bias=bias, metadata=meta)
