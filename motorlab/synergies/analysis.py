"""How many synergies, chosen on held-out data: cross-validated VAF and the field's criteria for N.

VAF ("variance accounted for") is defined two ways in this literature, and every result names which:
  - uncentred, for NMF on non-negative activations (Torres-Oviedo & Ting 2006; d'Avella et al. 2003):
    1 - SSE / sum(x^2), the share of the signal's total energy the synergies reconstruct;
  - centred, for PCA (and PCA -> ICA, whose reconstruction is PCA's): 1 - SSE / sum((x - mean)^2),
    the explained-variance ratio.
Cross-validation holds out whole episodes (K folds of episodes, sklearn's GroupKFold): samples within
an episode are strongly autocorrelated, so a random split of samples would score the fit on data it
has all but seen. The synergies are fitted on K - 1 folds; the held-out fold is reconstructed with
them (NMF: non-negative coefficients solved with the synergies fixed; PCA: projection on the
training components around the training mean) and scored.

Criteria for N (each named in what it returns):
  - "total-vaf": the smallest N whose total VAF reaches a threshold (0.90 is common);
  - "muscle-vaf": the smallest N at which every muscle's own VAF reaches a threshold (0.75 in
    Torres-Oviedo & Ting 2006), so no muscle is left unexplained behind a good total;
  - "elbow": d'Avella et al. 2003 / Cheung et al. 2005: the smallest N from which the rest of the VAF
    curve is a straight line, i.e. a linear fit to the curve's points N..max has mean squared error
    below 1e-4: past it, each synergy adds about the same small share, as noise would.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.processes import in_processes

ELBOW_MSE = 1e-4  # d'Avella et al. 2003
Definition = Literal["uncentred", "centred"]
DEFINITIONS = {"uncentred": "1 - SSE / sum(x^2) (uncentred, for NMF)",
               "centred": "1 - SSE / sum((x - mean)^2) (centred: PCA's explained-variance ratio)"}


def definition_of(method: str) -> Definition:
    """The VAF definition a fit method is scored with."""
    return "uncentred" if method == "nmf" else "centred"


@dataclass(frozen=True)
class CrossValidatedVaf:
    """VAF for N = 1..max_n: held out over K folds of episodes, or (folds = 0) in-sample, one fit on all."""

    method: str
    definition: Definition
    folds: int  # 0: in-sample (the curve of the data the synergies were fitted to)
    ns: list[int]
    total: np.ndarray  # (max(folds, 1), len(ns)): each fold's held-out total VAF
    muscle: np.ndarray  # (max(folds, 1), len(ns), n_muscles): each muscle's held-out VAF
    train: np.ndarray  # (max(folds, 1), len(ns)): the VAF on the folds it was fitted on, for comparison

    @property
    def held_out(self) -> bool:
        return self.folds > 0

    @property
    def where(self) -> str:
        """How the curve was scored, for tables and plots."""
        return (f"held-out VAF ({self.definition}), mean of {self.folds} folds of episodes" if self.held_out
                else f"in-sample VAF ({self.definition})")

    @property
    def mean(self) -> np.ndarray:
        return self.total.mean(axis=0)

    @property
    def std(self) -> np.ndarray:
        """The folds' standard deviation (zeros in-sample: one fit, no spread to show)."""
        return self.total.std(axis=0, ddof=1) if self.folds > 1 else np.zeros(len(self.ns))

    @property
    def muscle_mean(self) -> np.ndarray:
        return self.muscle.mean(axis=0)


@dataclass(frozen=True)
class Choice:
    """N as one criterion chose it (None: no N up to max_n meets it)."""

    criterion: Literal["total-vaf", "muscle-vaf", "elbow"]
    n: int | None
    threshold: float
    text: str  # "held-out VAF >= 0.90 (uncentred), 5 folds of episodes"


def vaf(x: np.ndarray, reconstruction: np.ndarray, definition: Definition, mean: np.ndarray | None = None) -> float:
    """Total VAF of a reconstruction; centred around `mean` (default the data's own)."""
    resid = np.sum((x - reconstruction) ** 2)
    centre = (x.mean(axis=0) if mean is None else mean) if definition == "centred" else 0.0
    energy = np.sum((x - centre) ** 2)
    return 1.0 - float(resid / energy) if energy > 0 else float("nan")


def muscle_vaf(x: np.ndarray, reconstruction: np.ndarray, definition: Definition,
               mean: np.ndarray | None = None) -> np.ndarray:
    """Each muscle's own VAF (a column's energy that the reconstruction accounts for); a silent muscle
    (no energy) counts as fully explained when the reconstruction is silent too."""
    resid = np.sum((x - reconstruction) ** 2, axis=0)
    centre = (x.mean(axis=0) if mean is None else mean) if definition == "centred" else 0.0
    energy = np.sum((x - centre) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 1.0 - resid / energy
    return np.where(energy > 0, out, np.where(resid > 0, -np.inf, 1.0))


# sklearn NMF's stopping tolerance for the scoring fits of a VAF curve (folds x N of them). Its default, 1e-4,
# spends most of a fit's iterations on digits the curve does not show: measured on 100k samples of the MyoSuite
# hand (39 muscles, pink-noise commands; one fold; N = 2..20; 5k-80k fit samples), 1e-3 stopped 3-24x sooner and
# moved the held-out VAF by at most 0.0012 (median 0.0004); on a hand set collected with another seed, 9-13x and
# at most 0.0009 (the folds' median spread: 0.0006). `synergies fit`'s final synergies keep the default.
CV_TOL = 1e-3


def _fit_and_score(method: str, n: int, train: np.ndarray, test: np.ndarray | None, seed: int
                   ) -> tuple[float, np.ndarray, float]:
    """(held-out total VAF, held-out per-muscle VAF, training VAF) of N synergies fitted on `train`; `test`
    None: in-sample (scored on `train`, its fit's own reconstruction, not a second solve)."""
    definition = definition_of(method)
    if method == "nmf":
        import warnings

        from sklearn.decomposition import NMF
        from sklearn.exceptions import ConvergenceWarning

        from motorlab.synergies.sar import NMF_INIT, NMF_MAX_ITER

        model = NMF(n_components=n, init=NMF_INIT, max_iter=NMF_MAX_ITER, tol=CV_TOL, random_state=seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            # float32: sklearn's NMF keeps the input's precision, and single precision fits in about 2/3 of the
            # time (a folds x N grid is ~100 fits); the VAF is scored in double precision below
            coef = model.fit_transform(train.astype(np.float32))
            # non-negative coefficients of the held-out samples with the synergies fixed
            held = coef if test is None else model.transform(test.astype(np.float32))
        w = model.components_.astype(np.float64)
        fitted, predicted, centre = coef.astype(np.float64) @ w, held.astype(np.float64) @ w, None
    else:
        from sklearn.decomposition import PCA

        pca = PCA(n_components=n, svd_solver="full").fit(train)
        fitted = pca.inverse_transform(pca.transform(train))
        predicted = fitted if test is None else pca.inverse_transform(pca.transform(test))
        centre = pca.mean_  # held-out data centred on what the fit knew
    scored = train if test is None else test
    return (vaf(scored, predicted, definition, centre), muscle_vaf(scored, predicted, definition, centre),
            vaf(train, fitted, definition))


def cross_validated_vaf(x: np.ndarray, episodes: np.ndarray, method: str = "nmf", max_n: int | None = None,
                        folds: int | None = 5, seed: int = 0, workers: int | None = None) -> CrossValidatedVaf:
    """Held-out VAF for N = 1..max_n over `folds` folds of episodes, folds and N in parallel (joblib);
    `folds` None or 0: in-sample, one fit per N on all the data.

    Raises:
        MotorlabError: fewer episodes than folds, negative activations for NMF, a bad max_n.
    """
    x = np.asarray(x, dtype=np.float64)
    episodes = np.asarray(episodes).ravel()
    if episodes.shape != (x.shape[0],):
        raise MotorlabError(f"one episode index per sample is needed; got {episodes.shape} for {x.shape[0]} samples.")
    m = x.shape[1]
    max_n = m if max_n is None else int(max_n)
    if not 1 <= max_n <= m:
        raise MotorlabError(f"--max-n must be in [1, {m}] (the number of muscles); got {max_n}.")
    distinct = np.unique(episodes).size
    folds = folds or 0
    if folds and (folds < 2 or distinct < folds):
        raise MotorlabError(f"--cv {folds} needs at least {max(folds, 2)} episodes to hold out, and the activations "
                            f"have {distinct}; collect more episodes or give a smaller --cv (at least 2).")
    if method == "nmf" and x.min() < 0:
        raise MotorlabError(f"NMF needs non-negative activations (the smallest is {x.min():.4g}); use --method pca.")
    from joblib import delayed
    from sklearn.model_selection import GroupKFold

    everything = np.arange(x.shape[0])
    splits = list(GroupKFold(n_splits=folds).split(x, groups=episodes)) if folds else [(everything, everything)]
    ns = list(range(1, max_n + 1))
    jobs = [(f, n) for f in range(len(splits)) for n in ns]
    # processes: NMF's and PCA's numpy work holds the GIL in parts; one job per core
    scored = in_processes((
        delayed(_fit_and_score)(method, n, *((x[splits[f][0]], x[splits[f][1]]) if folds else (x, None)), seed)
        for f, n in jobs), workers)
    k = len(splits)
    total, muscle, train = np.zeros((k, max_n)), np.zeros((k, max_n, m)), np.zeros((k, max_n))
    for (f, n), (held, per_muscle, fitted) in zip(jobs, scored):
        total[f, n - 1], muscle[f, n - 1], train[f, n - 1] = held, per_muscle, fitted
    return CrossValidatedVaf(method, definition_of(method), folds, ns, total, muscle, train)


def by_total(curve: np.ndarray, threshold: float) -> int | None:
    """The smallest N whose VAF reaches `threshold` (1e-12 of slack for rounding)."""
    hits = np.nonzero(np.asarray(curve) >= threshold - 1e-12)[0]
    return int(hits[0]) + 1 if hits.size else None


def by_muscle(muscle_curve: np.ndarray, threshold: float) -> int | None:
    """The smallest N at which every muscle's VAF reaches `threshold`; muscle_curve is (N, muscles)."""
    hits = np.nonzero(np.all(np.asarray(muscle_curve) >= threshold - 1e-12, axis=1))[0]
    return int(hits[0]) + 1 if hits.size else None


def by_elbow(curve: np.ndarray, mse: float = ELBOW_MSE) -> int | None:
    """The smallest N from which a straight line fits the rest of the curve (N..max) with mean squared
    error below `mse`; None for a curve of fewer than 3 points (every 2 points lie on a line)."""
    y = np.asarray(curve, dtype=np.float64)
    if y.size < 3:
        return None
    for start in range(y.size - 2):  # at least 3 points in the fit
        xs, ys = np.arange(start, y.size, dtype=np.float64), y[start:]
        slope, intercept = np.polyfit(xs, ys, 1)
        if float(np.mean((ys - (slope * xs + intercept)) ** 2)) < mse:
            return start + 1
    return None


def choices(cv: CrossValidatedVaf, threshold: float = 0.9, muscle_threshold: float = 0.75) -> list[Choice]:
    """N by each criterion on the held-out (mean over folds) curves."""
    where = cv.where
    return [Choice("total-vaf", by_total(cv.mean, threshold), threshold, f"total {where} >= {threshold:g}"),
            Choice("muscle-vaf", by_muscle(cv.muscle_mean, muscle_threshold), muscle_threshold,
                   f"every muscle's {where} >= {muscle_threshold:g}"),
            Choice("elbow", by_elbow(cv.mean), ELBOW_MSE,
                   f"elbow of the {where} curve: a line fits the rest with MSE < {ELBOW_MSE:g}")]
