"""SAR math core: fit recovers known synergies, VAF, batched affine decode, safe save/load."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest
from scipy.linalg import subspace_angles

from motorlab.errors import MotorlabError
from motorlab.synergies.sar import SAR, fit_sar, load_sar, save_sar, smallest_n, vaf_curve

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

K, M = 4, 12  # true synergies, muscles


def synthetic(seed: int = 0, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Activations from K known non-negative synergies: (activations (n, M), synergies (K, M)).

    Each synergy drives its own group of 3 muscles plus a sparse spill-over, with
    sparse non-Gaussian coefficients (what ICA needs); clipped to [0, 1], small noise.
    """
    rng = np.random.default_rng(seed)
    syn = 0.3 * rng.uniform(0, 1, (K, M)) * (rng.random((K, M)) < 0.3)
    for k in range(K):
        syn[k, 3 * k:3 * k + 3] += rng.uniform(0.5, 1.0, 3)
    coef = rng.exponential(1.0, (n, K)) * (rng.random((n, K)) < 0.6)
    x = coef @ syn
    x *= 0.8 / np.quantile(x, 0.99)
    x += rng.normal(0, 0.005, x.shape)
    return np.clip(x, 0, 1), syn


@pytest.fixture(scope="module")
def data() -> tuple[np.ndarray, np.ndarray]:
    return synthetic()


@pytest.fixture(scope="module")
def fitted(data) -> SAR:
    return fit_sar(data[0], n_synergies=K, method="pca-ica", source_env="myoHandReorient8-v0")


def max_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Largest principal angle between the row spaces of a and b."""
    return float(np.degrees(subspace_angles(a.T, b.T)).max())


@pytest.mark.parametrize("method", ["pca-ica", "pca", "nmf"])
def test_fit_recovers_true_synergy_span(data, method):
    x, syn = data
    sar = fit_sar(x, n_synergies=K, method=method)
    assert sar.weight.shape == (K, M) and sar.bias.shape == (M,)
    # decode(z) - bias = z @ weight: the span of the decode is the row space of weight.
    assert max_angle_deg(syn, sar.weight) < 5.0
    # Meaningful: an unrelated non-negative 4-D subspace is far from the truth.
    other = np.random.default_rng(99).uniform(0, 1, (K, M))
    assert max_angle_deg(syn, other) > 30.0
    # The scaler maps the training data's synergy coordinates onto [-1, 1] exactly.
    z = sar.encode(x)
    np.testing.assert_allclose(z.min(axis=0), -1.0, atol=1e-6 if method != "nmf" else 1e-3)
    np.testing.assert_allclose(z.max(axis=0), 1.0, atol=1e-6 if method != "nmf" else 1e-3)


@pytest.mark.parametrize("method", ["pca-ica", "pca"])
def test_encode_decode_reconstruction_matches_recorded_vaf(data, method):
    x, _ = data
    sar = fit_sar(x, n_synergies=3, method=method)
    rec = sar.decode(sar.encode(x))
    vaf = 1 - np.sum((x - rec) ** 2) / np.sum((x - x.mean(axis=0)) ** 2)
    assert vaf == pytest.approx(sar.metadata["vaf"], abs=1e-9)
    assert vaf == pytest.approx(vaf_curve(x)[2], abs=1e-9)


def test_vaf_threshold_picks_true_number_of_synergies(data):
    x, _ = data
    curve = vaf_curve(x, method="pca")
    sar = fit_sar(x, vaf=0.95, method="pca-ica")
    assert sar.n_synergies == K == smallest_n(curve, 0.95)
    assert curve[K - 2] < 0.95 <= curve[K - 1] == sar.metadata["vaf"]
    assert sar.metadata["vaf_threshold"] == 0.95


def test_nmf_vaf_threshold_consistent_with_its_curve(data):
    x, _ = data
    curve = vaf_curve(x, method="nmf", max_n=6)
    sar = fit_sar(x, vaf=0.95, method="nmf")
    assert sar.n_synergies == smallest_n(curve, 0.95) == K
    assert sar.metadata["vaf"] == pytest.approx(curve[K - 1], abs=1e-12)
    # the uncentered VAF of the decoded NMF reconstruction is the recorded one
    h = (sar.encode(x) - sar.arrays["scaler_min"]) / sar.arrays["scaler_scale"]
    rec = h @ sar.arrays["nmf_components"]
    assert 1 - np.sum((x - rec) ** 2) / np.sum(x**2) == pytest.approx(sar.metadata["vaf"], abs=1e-3)


def test_pca_vaf_curve_monotone_bounded_ends_at_one(data):
    x, _ = data
    curve = vaf_curve(x)
    assert curve.shape == (M,)
    assert np.all(np.diff(curve) >= 0)
    assert np.all(curve <= 1 + 1e-12) and curve[0] > 0
    assert curve[-1] == pytest.approx(1.0, abs=1e-12)
    # equals 1 - |X - X_hat|^2 / |X - mean|^2 of a rank-2 PCA reconstruction
    xc = x - x.mean(axis=0)
    u, s, vt = np.linalg.svd(xc, full_matrices=False)
    rec = (u[:, :2] * s[:2]) @ vt[:2]
    assert curve[1] == pytest.approx(1 - np.sum((xc - rec) ** 2) / np.sum(xc**2), abs=1e-12)
    # fewer samples than muscles: still length M and exactly 1 once N reaches the rank
    few = vaf_curve(x[:5])
    assert few.shape == (M,) and np.all(few[4:] == 1.0)


@pytest.mark.parametrize("shape", [(K,), (7, K), (2, 3, K)])
def test_decode_is_batched_affine(fitted, shape):
    z = np.random.default_rng(1).uniform(-1, 1, shape)
    out = fitted.decode(z)
    assert out.shape == shape[:-1] + (M,) and out.dtype == np.float64
    flat = z.reshape(-1, K)
    rows = np.stack([fitted.decode(row) for row in flat])
    np.testing.assert_allclose(out.reshape(-1, M), rows, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rows, flat @ fitted.weight + fitted.bias, rtol=0, atol=1e-12)
    # float32 and list input give the same float64 result
    np.testing.assert_allclose(fitted.decode(z.astype(np.float32).tolist()), fitted.decode(z.astype(np.float32)),
                               atol=1e-12)


@pytest.mark.parametrize("bad", [np.zeros(K + 1), np.zeros((3, K - 1)), np.float64(0.5), np.zeros((K, 0))])
def test_decode_wrong_last_dim_names_both_sizes(fitted, bad):
    with pytest.raises(MotorlabError, match=rf"{K} synergies.*{M} muscles"):
        fitted.decode(bad)


def test_decode_matches_sklearn_chain_for_a_motorlab_fit(data, fitted):
    """Rebuild the same sklearn chain from the plain arrays and compare."""
    from sklearn.decomposition import PCA, FastICA
    from sklearn.preprocessing import MinMaxScaler

    a = fitted.arrays
    pca = PCA(n_components=K)
    pca.mean_, pca.components_, pca.explained_variance_ = a["pca_mean"], a["pca_components"], a[
        "pca_explained_variance"]
    pca.n_features_in_, pca.n_components_ = M, K
    ica = FastICA(whiten="unit-variance")
    ica.mixing_, ica.mean_, ica.components_, ica.n_features_in_ = a["ica_mixing"], a["ica_mean"], a[
        "ica_components"], K
    scaler = MinMaxScaler(feature_range=(-1, 1))
    scaler.min_, scaler.scale_, scaler.n_features_in_ = a["scaler_min"], a["scaler_scale"], K
    z = np.random.default_rng(2).uniform(-1, 1, (500, K))
    chain = pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))
    np.testing.assert_allclose(fitted.decode(z), chain, rtol=1e-9, atol=1e-9)
    # and the forward chain agrees with encode
    np.testing.assert_allclose(fitted.encode(data[0]), scaler.transform(ica.transform(pca.transform(data[0]))),
                               atol=1e-9)


def test_fit_is_deterministic_and_metadata_is_json(data):
    x, _ = data
    a = fit_sar(x, n_synergies=3, seed=5, source_env="env-v0")
    b = fit_sar(x, n_synergies=3, seed=5)
    assert np.array_equal(a.weight, b.weight) and np.array_equal(a.bias, b.bias)
    meta = json.loads(json.dumps(a.metadata))
    assert meta["method"] == "pca-ica" and meta["n_synergies"] == 3 and meta["n_muscles"] == M
    assert meta["source_env"] == "env-v0" and 0 < meta["vaf"] <= 1
    assert set(meta["versions"]) == {"numpy", "sklearn", "motorlab"}
    assert meta["pca_whiten"] is False and meta["ica_whiten"] == "unit-variance"


def test_weights_are_read_only(fitted):
    with pytest.raises(ValueError):
        fitted.weight[0, 0] = 1.0


def test_save_load_round_trip_identical(tmp_path, data):
    for method in ("pca-ica", "pca", "nmf"):
        sar = fit_sar(data[0], n_synergies=3, method=method, source_env="myoLegWalk-v0")
        path = save_sar(sar, tmp_path / f"{method}.npz")
        loaded = load_sar(path)
        z = np.random.default_rng(3).uniform(-1, 1, (10, 3))
        assert loaded.method == method
        assert np.array_equal(loaded.decode(z), sar.decode(z))
        assert loaded.metadata == json.loads(json.dumps(sar.metadata))
        assert set(loaded.arrays) == set(sar.arrays)
        # plain arrays only: readable with pickling disabled
        with np.load(path, allow_pickle=False) as npz:
            assert all(npz[k].dtype != object for k in npz.files)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nmf.npz", "pca-ica.npz", "pca.npz"]  # no temp files


def _rewrite(path, src, change):
    """Copy the npz at src to path with `change(dict)` applied."""
    with np.load(src, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    change(data)
    buf = io.BytesIO()
    np.savez(buf, **data)
    path.write_bytes(buf.getvalue())
    return path


def _tamper_weight(d):
    d["decode_weight"] = d["decode_weight"].copy()
    d["decode_weight"][0, 0] += 1e-3


def _set(key, value):
    return lambda d: d.__setitem__(key, value)


@pytest.mark.parametrize("change, fragment", [
    (lambda d: d.pop("ica_mixing"), "missing array(s) ica_mixing"),
    (lambda d: d.__setitem__("pca_mixing", d.pop("ica_mixing")), "ica_mixing"),
    (lambda d: d.pop("metadata"), "missing key(s) metadata"),
    (_tamper_weight, "differs from the one its arrays imply"),
    (lambda d: d.__setitem__("scaler_min", d["scaler_min"][:-1]), "shape"),
    (lambda d: d.__setitem__("pca_mean", np.full_like(d["pca_mean"], np.nan)), "non-finite"),
    (_set("metadata", np.array("{not json")), "not valid JSON"),
    (_set("metadata", np.array(json.dumps({"method": "magic"}))), "'magic'"),
])
def test_corrupt_files_give_clear_errors(tmp_path, fitted, change, fragment):
    good = save_sar(fitted, tmp_path / "good.npz")
    bad = _rewrite(tmp_path / "bad.npz", good, change)
    with pytest.raises(MotorlabError, match="bad.npz") as err:
        load_sar(bad)
    assert fragment in str(err.value)


def test_truncated_missing_and_foreign_files(tmp_path, fitted):
    good = save_sar(fitted, tmp_path / "good.npz")
    data = good.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(MotorlabError, match="cut.npz.*corrupt"):
        load_sar(tmp_path / "cut.npz")
    with pytest.raises(MotorlabError, match="does not exist"):
        load_sar(tmp_path / "nope.npz")
    np.save(tmp_path / "single.npy", np.zeros(3))
    with pytest.raises(MotorlabError, match="single .npy"):
        load_sar(tmp_path / "single.npy")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(MotorlabError, match="text.npz"):
        load_sar(tmp_path / "text.npz")
    # an npz holding a pickled object array is refused, never unpickled
    buf = io.BytesIO()
    np.savez(buf, metadata=np.array([{"a": 1}], dtype=object))
    (tmp_path / "pickled.npz").write_bytes(buf.getvalue())
    with pytest.raises(MotorlabError, match="pickled.npz"):
        load_sar(tmp_path / "pickled.npz")
    assert zipfile.is_zipfile(good)


@pytest.mark.parametrize("activations, kwargs, fragment", [
    (np.full((10, 4), np.nan), {"n_synergies": 2}, "non-finite"),
    (np.zeros(10), {"n_synergies": 1}, "2-D"),
    (np.zeros((1, 4)), {"n_synergies": 1}, "at least 2 samples"),
    ("rand", {"n_synergies": 0}, "[1, 4]"),
    ("rand", {"n_synergies": 5}, "[1, 4]"),
    ("rand", {"n_synergies": 2.0}, "integer"),
    ("rand", {}, "exactly one"),
    ("rand", {"n_synergies": 2, "vaf": 0.9}, "exactly one"),
    ("rand", {"vaf": 1.5}, "(0, 1]"),
    ("rand", {"vaf": 0.0}, "(0, 1]"),
    ("rand", {"n_synergies": 2, "method": "ica"}, "unknown synergy method"),
    ("neg", {"n_synergies": 2, "method": "nmf"}, "non-negative"),
    ("rank1", {"n_synergies": 3}, "only 1 independent"),
    (np.ones((10, 4)), {"vaf": 0.9}, "zero variance"),
])
def test_fit_rejects_bad_inputs(activations, kwargs, fragment):
    rng = np.random.default_rng(0)
    if isinstance(activations, str):
        activations = {"rand": rng.random((20, 4)), "neg": rng.random((20, 4)) - 0.5,
                       "rank1": np.outer(rng.random(20), rng.random(4))}[activations]
    with pytest.raises(MotorlabError) as err:
        fit_sar(activations, **kwargs)
    assert fragment in str(err.value)


def test_smallest_n_and_vaf_curve_errors(data):
    assert smallest_n([0.5, 0.9, 0.97, 0.99], 0.95) == 3
    assert smallest_n([0.5, 0.9], 0.5) == 1
    with pytest.raises(MotorlabError, match="best: 0.900000"):
        smallest_n([0.5, 0.9], 0.95)
    with pytest.raises(MotorlabError, match="max_n"):
        vaf_curve(data[0], max_n=M + 1)
