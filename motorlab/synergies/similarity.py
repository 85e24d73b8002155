"""How alike two synergy sets are, against what chance gives.

Similarity of two synergies is the cosine of their muscle-weight vectors (Tresch et al. 2006; Cheung et
al. 2005). NMF synergies are non-negative, so the plain cosine; PCA and ICA directions have no sign of
their own (a synergy and its negation are the same synergy), so the absolute cosine. Two sets are paired
one to one by the assignment that maximizes the summed similarity (the Hungarian method,
scipy.optimize.linear_sum_assignment).

Chance: surrogate data with each muscle's activations shuffled independently in time keep every
muscle's distribution but break the co-activation that synergies describe. Synergies re-fitted to each
surrogate (same method, same N) and matched to the other set the same way give the similarities chance
reaches; their 95th percentile is the level a matched pair must exceed to count as similar.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motorlab.errors import MotorlabError
from motorlab.processes import in_processes


@dataclass(frozen=True)
class Matching:
    """Set A's synergies paired one to one with set B's."""

    pairs: list[tuple[int, int]]  # (index in A, index in B), by A's index
    similarity: list[float]  # each pair's cosine
    absolute: bool  # |cos| (PCA / ICA directions) or cos (NMF)

    @property
    def mean(self) -> float:
        return float(np.mean(self.similarity)) if self.similarity else float("nan")


def cosine_matrix(a: np.ndarray, b: np.ndarray, absolute: bool) -> np.ndarray:
    """cos(a_i, b_j) for the rows of a (n_a, muscles) and b (n_b, muscles); a zero row has cosine 0."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise MotorlabError(f"synergy sets must be (synergies, muscles) over the same muscles; got {a.shape} and {b.shape}.")
    na, nb = np.linalg.norm(a, axis=1, keepdims=True), np.linalg.norm(b, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (a / np.where(na > 0, na, 1)) @ (b / np.where(nb > 0, nb, 1)).T
    return np.abs(c) if absolute else c


def match(a: np.ndarray, b: np.ndarray, absolute: bool = False) -> Matching:
    """The one-to-one pairing of a's and b's synergies with the largest summed cosine (min(n_a, n_b) pairs)."""
    from scipy.optimize import linear_sum_assignment

    c = cosine_matrix(a, b, absolute)
    rows, cols = linear_sum_assignment(c, maximize=True)
    order = np.argsort(rows)
    return Matching([(int(rows[i]), int(cols[i])) for i in order], [float(c[rows[i], cols[i]]) for i in order],
                    absolute)


def shuffled(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Each muscle's samples permuted independently (a surrogate: same marginals, no co-activation)."""
    return np.column_stack([rng.permutation(x[:, j]) for j in range(x.shape[1])])


@dataclass(frozen=True)
class Null:
    """Chance similarity from surrogates."""

    surrogates: int
    samples: int  # samples per surrogate fit
    pair_similarities: np.ndarray  # every matched pair's cosine over every surrogate
    mean_similarities: np.ndarray  # each surrogate's mean matched cosine

    @property
    def p95(self) -> float:
        return float(np.percentile(self.pair_similarities, 95))

    @property
    def mean_p95(self) -> float:
        return float(np.percentile(self.mean_similarities, 95))


def _surrogate(reference: np.ndarray, x: np.ndarray, method: str, n: int, seed: int, absolute: bool) -> list[float]:
    from motorlab.synergies.vectors import fitted_vectors

    rng = np.random.default_rng(seed)
    return match(reference, fitted_vectors(shuffled(x, rng), method, n, seed), absolute).similarity


def chance(reference: np.ndarray, x: np.ndarray, method: str, n: int, surrogates: int = 100, seed: int = 0,
           max_samples: int | None = None, workers: int | None = None) -> Null:
    """Similarities of `reference` (n_ref, muscles) to synergies fitted to `surrogates` shuffles of x.

    `max_samples`: each surrogate is fitted to at most this many samples, drawn once at random; None: all of
    them, the default, so that a surrogate's fit is the reference's fit (same samples, method, N and
    tolerance) on data without co-activation. A smaller draw is faster but not neutral: on 100k samples of
    the MyoSuite hand (N = 10) the null's p95 fell from 0.87 (all) to 0.80 (20k) and 0.74 (10k), a chance
    level too low, so pairs would pass it that should not (benchmarks/synergy_analysis.py records it).
    Surrogates run in parallel (joblib)."""
    from joblib import delayed

    x = np.asarray(x, dtype=np.float64)
    rng = np.random.default_rng(seed)
    if max_samples is not None and x.shape[0] > max_samples:
        x = x[np.sort(rng.choice(x.shape[0], max_samples, replace=False))]
    absolute = method != "nmf"
    seeds = rng.integers(0, 2**31 - 1, size=surrogates)
    sims = in_processes((delayed(_surrogate)(reference, x, method, n, int(s), absolute) for s in seeds), workers)
    return Null(surrogates, x.shape[0], np.concatenate([np.asarray(s) for s in sims]),
                np.array([float(np.mean(s)) for s in sims]))


def aligned(names_a: list[str], names_b: list[str]) -> np.ndarray:
    """The column order that puts set B's muscles in set A's order.

    Raises:
        MotorlabError: the two sets' muscles differ, naming the names only one side has.
    """
    if len(set(names_a)) != len(names_a) or len(set(names_b)) != len(names_b):
        raise MotorlabError("a synergy set names a muscle twice; fit it again from activations with distinct names.")
    only_a, only_b = sorted(set(names_a) - set(names_b)), sorted(set(names_b) - set(names_a))
    if only_a or only_b:
        def some(x: list[str]) -> str:
            return ", ".join(x[:6]) + (f" and {len(x) - 6} more" if len(x) > 6 else "") if x else "none"

        raise MotorlabError(f"the two synergy sets are over different muscles (only in A: {some(only_a)}; only in B: "
                            f"{some(only_b)}): synergies compare only over the same named muscles.")
    where = {name: j for j, name in enumerate(names_b)}
    return np.array([where[name] for name in names_a])
