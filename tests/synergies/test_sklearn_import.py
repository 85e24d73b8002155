"""Importing scikit-learn SAR pickles: trust gate, exact agreement with sklearn's chain."""

from __future__ import annotations

import warnings
from pathlib import Path

import joblib
import numpy as np
import pytest
from sklearn.decomposition import PCA, FastICA
from sklearn.preprocessing import MinMaxScaler

from motorlab.errors import MotorlabError
from motorlab.synergies.sar import load_sar
from motorlab.synergies.sklearn_import import import_sklearn

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

PUBLISHED = Path(__file__).resolve().parents[3] / "shared/data/myosuite_sar_pretrained"


def chain(pca, ica, scaler, z):
    return pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))


def write_sklearn_sar(folder: Path, pca_whiten=False, ica_whiten="unit-variance", feature_range=(-1, 1),
                      n_pca=5, n_ica=None, seed=0):
    """Fit PCA -> FastICA -> MinMaxScaler on random activations and pickle them like MyoSuite does."""
    rng = np.random.default_rng(seed)
    x = np.clip(rng.exponential(0.2, (300, 4)) @ rng.uniform(0, 1, (4, 10)) + rng.uniform(0, 0.05, (300, 10)), 0, 1)
    pca = PCA(n_components=n_pca, whiten=pca_whiten).fit(x)
    scores = pca.transform(x)
    ica = FastICA(n_components=n_ica, whiten=ica_whiten, random_state=seed, max_iter=500,
                  whiten_solver="eigh")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # convergence / n_components-ignored warnings are not under test
        sources = ica.fit_transform(scores)
    scaler = MinMaxScaler(feature_range=feature_range).fit(sources)
    folder.mkdir(parents=True, exist_ok=True)
    joblib.dump(pca, folder / "pca.pkl")
    joblib.dump(ica, folder / "ica.pkl")
    joblib.dump(scaler, folder / "normalizer.pkl")
    return pca, ica, scaler


@pytest.mark.parametrize("pca_whiten", [False, True])
@pytest.mark.parametrize("ica_whiten", ["unit-variance", "arbitrary-variance"])
@pytest.mark.parametrize("feature_range", [(-1, 1), (0, 1)])
def test_import_round_trip_matches_sklearn_chain(tmp_path, pca_whiten, ica_whiten, feature_range):
    pca, ica, scaler = write_sklearn_sar(tmp_path / "src", pca_whiten, ica_whiten, feature_range)
    out = tmp_path / "sar.npz"
    sar = import_sklearn(tmp_path / "src", trust=True, out=out)
    assert sar.method == "sklearn-import" and (sar.n_synergies, sar.n_muscles) == (5, 10)
    assert sar.metadata["import_check_max_abs_error"] <= 1e-6
    assert sar.metadata["sklearn_versions_differ"] is False
    lo, hi = feature_range
    z = np.random.default_rng(7).uniform(lo, hi, (2000, 5))  # other points than the import check used
    expected = chain(pca, ica, scaler, z)
    np.testing.assert_allclose(sar.decode(z), expected, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(load_sar(out).decode(z), expected, rtol=1e-9, atol=1e-6)
    # the forward chain agrees too
    x = pca.inverse_transform(pca.transform(np.random.default_rng(8).uniform(0, 1, (50, 10))))
    np.testing.assert_allclose(sar.encode(x), scaler.transform(ica.transform(pca.transform(x))), atol=1e-8)


@pytest.mark.parametrize("ica_whiten, n_pca, n_ica", [(False, 4, None), ("unit-variance", 6, 3)])
def test_import_unwhitened_ica_and_fewer_sources_than_pcs(tmp_path, ica_whiten, n_pca, n_ica):
    pca, ica, scaler = write_sklearn_sar(tmp_path / "src", True, ica_whiten, (-1, 1), n_pca=n_pca, n_ica=n_ica)
    sar = import_sklearn(tmp_path / "src", trust=True, out=tmp_path / "sar.npz")
    n = n_ica or n_pca
    assert sar.n_synergies == n
    z = np.random.default_rng(9).uniform(-1, 1, (500, n))
    np.testing.assert_allclose(sar.decode(z), chain(pca, ica, scaler, z), rtol=1e-9, atol=1e-6)


def test_import_without_trust_writes_nothing(tmp_path):
    write_sklearn_sar(tmp_path / "src")
    out = tmp_path / "out" / "sar.npz"
    with pytest.raises(MotorlabError, match=r"arbitrary code.*--trust"):
        import_sklearn(tmp_path / "src", trust=False, out=out)
    assert not out.exists() and not out.parent.exists()


def test_import_missing_pickle_named_before_trust(tmp_path):
    write_sklearn_sar(tmp_path / "src")
    (tmp_path / "src" / "ica.pkl").unlink()
    with pytest.raises(MotorlabError, match=r"ica\.pkl is missing"):
        import_sklearn(tmp_path / "src", trust=False, out=tmp_path / "sar.npz")
    with pytest.raises(MotorlabError, match="does not exist"):
        import_sklearn(tmp_path / "nowhere", trust=True, out=tmp_path / "sar.npz")
    assert not (tmp_path / "sar.npz").exists()


def test_import_wrong_object_or_mismatched_pickles(tmp_path):
    write_sklearn_sar(tmp_path / "src")
    joblib.dump({"not": "a scaler"}, tmp_path / "src" / "normalizer.pkl")
    with pytest.raises(MotorlabError, match=r"normalizer\.pkl holds a builtins\.dict"):
        import_sklearn(tmp_path / "src", trust=True, out=tmp_path / "sar.npz")
    # a scaler for 3 features after an ICA with 5 sources: the chain does not compose
    joblib.dump(MinMaxScaler().fit(np.random.default_rng(0).random((10, 3))), tmp_path / "src" / "normalizer.pkl")
    with pytest.raises(MotorlabError, match="do not chain together"):
        import_sklearn(tmp_path / "src", trust=True, out=tmp_path / "sar.npz")
    (tmp_path / "src" / "pca.pkl").write_bytes(b"garbage")
    with pytest.raises(MotorlabError, match=r"cannot unpickle .*pca\.pkl"):
        import_sklearn(tmp_path / "src", trust=True, out=tmp_path / "sar.npz")
    assert not (tmp_path / "sar.npz").exists()


def test_import_disagreeing_with_sklearn_writes_nothing(tmp_path, monkeypatch):
    write_sklearn_sar(tmp_path / "src")
    original = PCA.inverse_transform
    monkeypatch.setattr(PCA, "inverse_transform", lambda self, X: original(self, X) + 1e-4)
    with pytest.raises(MotorlabError, match="disagrees with scikit-learn"):
        import_sklearn(tmp_path / "src", trust=True, out=tmp_path / "sar.npz")
    assert not (tmp_path / "sar.npz").exists()


@pytest.mark.parametrize("name, n_muscles", [("locomotion", 80), ("manipulation", 39)])
def test_published_myosuite_sar_imports_exactly(tmp_path, name, n_muscles):
    assert PUBLISHED.is_dir(), f"reference data missing at {PUBLISHED}"
    out = tmp_path / "sar.npz"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the old-version warnings are handled, not shown
        sar = import_sklearn(PUBLISHED / name, trust=True, out=out)
    assert (sar.n_synergies, sar.n_muscles) == (20, n_muscles)
    meta = sar.metadata
    assert meta["sklearn_versions_differ"] is True and meta["pickled_sklearn_versions"] == ["1.1.2"]
    assert meta["ica_whiten"] == "warn" and meta["import_check_max_abs_error"] <= 1e-6
    # check against the pickled chain ourselves, on fresh points
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pca, ica, scaler = (joblib.load(PUBLISHED / name / f) for f in ("pca.pkl", "ica.pkl", "normalizer.pkl"))
    z = np.random.default_rng(11).uniform(-1, 1, (1000, 20))
    np.testing.assert_allclose(sar.decode(z), chain(pca, ica, scaler, z), rtol=1e-9, atol=1e-6)
    loaded = load_sar(out)
    assert np.array_equal(loaded.decode(z), sar.decode(z))
