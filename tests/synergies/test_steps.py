"""`motorlab synergies vaf|fit|import-sklearn` from the command line: the files they
write, and one-line errors for the files a user can get wrong."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from motorlab.api.synergies import load_sar
from tests.helpers import (
    HAND_ID,
    HAND_MUSCLES,
    PUBLISHED_SAR,
    assert_ok,
    assert_one_line_error,
    assert_png,
    read_summary,
    run_cli,
    run_here,
)


@pytest.fixture(scope="module")
def vaf_dir(hand_activations, tmp_path_factory):
    out = tmp_path_factory.mktemp("vaf") / "vaf"
    proc = run_cli("synergies", "vaf", hand_activations, "--threshold", "0.8", "--out", out)
    assert_ok(proc)
    return out, proc


def test_vaf_writes_a_monotone_curve_and_the_smallest_n(vaf_dir):
    out, proc = vaf_dir
    assert_png(out / "vaf.png")
    s = read_summary(out)
    vaf = np.array(s["vaf"])
    assert s["n_muscles"] == HAND_MUSCLES and vaf.shape == (HAND_MUSCLES,)
    assert np.all(np.diff(vaf) >= 0) and np.all(vaf <= 1.0) and vaf[0] > 0
    assert vaf[-1] == pytest.approx(1.0)
    n = s["n_for_threshold"]
    assert vaf[n - 1] >= 0.8 and (n == 1 or vaf[n - 2] < 0.8)
    assert f"VAF >= 80%: {n}" in proc.stdout
    with np.load(_acts(out), allow_pickle=False) as d:
        assert s["samples"] == d["activations"].shape[0]


def _acts(vaf_out):
    """The activations file a vaf run read (recorded in its config.toml)."""
    import tomllib

    return tomllib.loads((vaf_out / "config.toml").read_text())["activations"]


@pytest.mark.fast  # make test-fast: this workflow's end-to-end test
def test_fit_by_vaf_writes_a_loadable_sar(hand_activations, vaf_dir, tmp_path):
    out = tmp_path / "fit"
    # the folder holding activations.npz works as well as the file
    proc = run_cli("synergies", "fit", hand_activations.parent, "--vaf", "0.8", "--out", out)
    assert_ok(proc)
    sar = load_sar(out / "sar.npz")
    s = read_summary(out)
    assert sar.n_muscles == s["n_muscles"] == HAND_MUSCLES
    # the same N the VAF step reported for the same threshold
    assert sar.n_synergies == s["n_synergies"] == read_summary(vaf_dir[0])["n_for_threshold"]
    assert s["vaf"] >= 0.8 and s["source_env"] == HAND_ID
    assert sar.metadata["source_env"] == HAND_ID and sar.metadata["method"] == "pca-ica"
    # decoded synergies are muscle commands: the scaled range [-1, 1] maps to finite activations
    z = np.random.default_rng(0).uniform(-1, 1, (16, sar.n_synergies))
    assert sar.decode(z).shape == (16, HAND_MUSCLES) and np.all(np.isfinite(sar.decode(z)))


def test_fit_by_n(hand_activations, tmp_path):
    out = tmp_path / "fit"
    assert_ok(run_cli("synergies", "fit", hand_activations, "--n", "5", "--method", "pca", "--out", out))
    sar = load_sar(out / "sar.npz")
    assert (sar.n_synergies, sar.n_muscles) == (5, HAND_MUSCLES) and sar.method == "pca"


def test_fit_with_both_n_and_vaf(hand_activations, tmp_path):
    proc = run_here("synergies", "fit", hand_activations, "--n", "5", "--vaf", "0.8", "--out", tmp_path / "fit")
    assert_one_line_error(proc, "--n-synergies", "--vaf")
    assert not (tmp_path / "fit").exists()


# ---- activations files a user can get wrong ---------------------------------------------

def bad_files(tmp_path):
    rng = np.random.default_rng(0)
    (tmp_path / "random.npz").write_bytes(rng.bytes(4096))
    nan = rng.uniform(0, 1, (50, 6))
    nan[7, 2] = np.nan
    np.savez(tmp_path / "nan.npz", activations=nan)
    np.savez(tmp_path / "other.npz", acts=rng.uniform(0, 1, (50, 6)), episode=np.zeros(50))
    np.save(tmp_path / "plain.npy", rng.uniform(0, 1, (50, 6)))


BAD_FILES = [
    ("missing.npz", ["missing.npz", "does not exist"]),
    ("random.npz", ["random.npz", "not a readable .npz"]),
    ("nan.npz", ["nan.npz", "NaN"]),
    ("other.npz", ["other.npz", "no 'activations' array", "acts"]),
    ("plain.npy", ["plain.npy"]),  # a plain .npy array instead of the .npz collect writes
]


@pytest.mark.parametrize("command", ["vaf", "fit"])
@pytest.mark.parametrize("name, fragments", BAD_FILES, ids=[n for n, _ in BAD_FILES])
def test_bad_activations_file(tmp_path, command, name, fragments):
    bad_files(tmp_path)
    extra = ["--vaf", "0.8"] if command == "fit" else []
    proc = run_here("synergies", command, tmp_path / name, *extra, "--out", tmp_path / "out")
    assert_one_line_error(proc, *fragments)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("threshold", ["1.5", "0"])
def test_vaf_threshold_out_of_range(hand_activations, tmp_path, threshold):
    """A VAF threshold is a fraction in (0, 1], as `fit --vaf` and recipes insist."""
    proc = run_here("synergies", "vaf", hand_activations, "--threshold", threshold, "--out", tmp_path / "out")
    assert_one_line_error(proc, "--threshold", "than or equal to 1" if threshold == "1.5" else "greater than 0")
    assert not (tmp_path / "out" / "summary.json").exists()


# ---- import-sklearn ---------------------------------------------------------------------

def test_import_sklearn_needs_trust(tmp_path):
    out = tmp_path / "hand.npz"
    proc = run_here("synergies", "import-sklearn", PUBLISHED_SAR / "manipulation", "--out", out)
    assert_one_line_error(proc, "--trust", "arbitrary code")
    assert not out.exists()


def test_import_sklearn_with_trust(tmp_path):
    import joblib

    out = tmp_path / "hand.npz"
    proc = run_cli("synergies", "import-sklearn", PUBLISHED_SAR / "manipulation", "--trust", "--out", out)
    assert_ok(proc)
    sar = load_sar(out)
    assert (sar.n_synergies, sar.n_muscles) == (20, HAND_MUSCLES)
    assert f"{sar.n_synergies} synergies x {sar.n_muscles} muscles" in proc.stdout
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pickled with an older scikit-learn
        pca, ica, scaler = (joblib.load(PUBLISHED_SAR / "manipulation" / f)
                            for f in ("pca.pkl", "ica.pkl", "normalizer.pkl"))
        z = np.random.default_rng(5).uniform(-1, 1, (8, sar.n_synergies))
        expected = pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z)))
    np.testing.assert_allclose(sar.decode(z), expected, atol=1e-6)
    assert json.loads(json.dumps(sar.metadata))["method"] == "sklearn-import"
