"""Every published SAR format, both directions: MyoSuite 3.0 SynergyModel folders import exactly
(whitening and scaler margin whatever their values), and motorlab SARs export to folders that
MyoSuite's own `load_synergy_model` reads and decodes exactly as motorlab does."""

from __future__ import annotations

import dataclasses
import io
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from myosuite.integrations.musclemimic import sar_extraction
from myosuite.integrations.musclemimic.sar_extraction import (
    extract_synergies,
    load_synergy_model,
    save_synergy_model,
)

from motorlab.errors import MotorlabError
from motorlab.synergies.sar import fit_sar, load_sar, save_sar
from motorlab.synergies.sklearn_export import export_sklearn
from motorlab.synergies.sklearn_import import SYNERGY_MODEL, TUTORIAL, import_sklearn, read_synergy_metadata
from tests.helpers import PUBLISHED_SAR, assert_ok, assert_one_line_error, run_cli, run_here
from tests.test_safe_loading import exploit

N_SYN, N_MUSCLES = 5, 12
EXACT = 1e-9  # the decode maps agree to float64 rounding, far inside this


def activations(seed: int = 0, n: int = 400) -> np.ndarray:
    """Synthetic muscle activations in [0, 1]: a few drives mixed into N_MUSCLES muscles, plus noise."""
    rng = np.random.default_rng(seed)
    x = rng.exponential(0.2, (n, 4)) @ rng.uniform(0, 1, (4, N_MUSCLES)) + rng.uniform(0, 0.05, (n, N_MUSCLES))
    return np.clip(x, 0, 1)


def myosuite_model(margin: float = 0.1, pca_whiten: bool = True, seed: int = 0):
    """A SynergyModel from MyoSuite's own extract_synergies; pca_whiten=False turns the (always whitened)
    PCA into an unwhitened one, still a valid chain, so both settings are covered."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # FastICA convergence on synthetic data is not under test
        model = extract_synergies(activations(seed), N_SYN, random_state=seed, scaler_margin=margin,
                                  source_clips=["clips/walk.npz", "clips/run.npz"])
    model.pca.whiten = pca_whiten
    return model


def myosuite_decode(model, z: np.ndarray) -> np.ndarray:
    """MyoSuite's decode of synergies to muscle activations (sar_torch_transform's chain, in sklearn)."""
    return model.pca.inverse_transform(model.ica.inverse_transform(model.scaler.inverse_transform(z)))


def max_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


# ---- MyoSuite 3.0 folder -> motorlab --------------------------------------------------------------

@pytest.mark.parametrize("margin", [0.0, 0.1, 0.25])
@pytest.mark.parametrize("pca_whiten", [True, False])
def test_myosuite_folder_imports_exactly(tmp_path, margin, pca_whiten):
    model = myosuite_model(margin, pca_whiten)
    save_synergy_model(model, tmp_path / "myo")
    sar = import_sklearn(tmp_path / "myo", trust=True, out=tmp_path / "sar.npz")
    assert (sar.n_synergies, sar.n_muscles) == (N_SYN, N_MUSCLES)
    loaded = load_synergy_model(tmp_path / "myo")
    # inside the synergy range and past it (a policy's action may overshoot before clipping)
    z = np.random.default_rng(3).uniform(-0.2, 1.2, (2000, N_SYN))
    assert max_diff(sar.decode(z), myosuite_decode(loaded, z)) < EXACT
    assert max_diff(load_sar(tmp_path / "sar.npz").decode(z), myosuite_decode(loaded, z)) < EXACT
    x = activations(1)[:50]  # the forward chain agrees too
    assert max_diff(sar.encode(x), loaded.scaler.transform(loaded.ica.transform(loaded.pca.transform(x)))) < EXACT
    meta = sar.metadata
    assert meta["import_format"] == SYNERGY_MODEL and meta["pca_whiten"] is pca_whiten
    assert meta["scaler_feature_range"] == [0.0, 1.0] and meta["import_check_max_abs_error"] < EXACT
    assert meta["myosuite_metadata"]["n_synergies"] == N_SYN
    assert meta["source_clips"] == ["clips/walk.npz", "clips/run.npz"]
    assert meta["scaler_margin"] is None  # MyoSuite 3.0.0 folds it into the scaler and stores none


def test_metadata_extras_are_kept_and_read_without_pickle(tmp_path):
    """A folder whose metadata.npz holds only plain arrays (margin, muscle names) is read pickle-free,
    and what it records lands in the SAR's metadata; a disagreeing synergy count is refused."""
    model = myosuite_model(0.25)
    save_synergy_model(model, tmp_path / "myo")
    names = [f"muscle{i}" for i in range(N_MUSCLES)]
    np.savez(tmp_path / "myo" / "metadata.npz", n_synergies=np.int32(N_SYN), n_muscles=np.int32(N_MUSCLES),
             vaf=np.float32(model.vaf), scaler_margin=np.float64(0.25), muscle_names=np.array(names),
             source_clips=np.array(["a.npz"]))
    assert read_synergy_metadata(tmp_path / "myo" / "metadata.npz", trust=False)["muscle_names"] == names
    sar = import_sklearn(tmp_path / "myo", trust=True, out=tmp_path / "sar.npz")
    assert sar.metadata["scaler_margin"] == 0.25 and sar.metadata["muscle_names"] == names
    assert sar.metadata["source_clips"] == ["a.npz"]
    np.savez(tmp_path / "myo" / "metadata.npz", n_synergies=np.int32(N_SYN + 1))
    with pytest.raises(MotorlabError, match="n_synergies = 6, but the pickles hold 5"):
        import_sklearn(tmp_path / "myo", trust=True, out=tmp_path / "other.npz")
    assert not (tmp_path / "other.npz").exists()


def trapped_metadata(path: Path, marker: Path) -> None:
    """metadata.npz whose source_clips object array is a pickle that creates `marker` when loaded."""
    npy = io.BytesIO()
    np.lib.format.write_array_header_1_0(npy, {"descr": "|O", "fortran_order": False, "shape": (1,)})
    npy.write(exploit(marker))
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("n_synergies.npy", _npy(np.int32(N_SYN)))
        z.writestr("source_clips.npy", npy.getvalue())


def _npy(value) -> bytes:
    buf = io.BytesIO()
    np.save(buf, value)
    return buf.getvalue()


def test_without_trust_nothing_is_unpickled(tmp_path):
    """Booby-trapped pickles and metadata.npz: without --trust, one line, nothing runs, nothing is written."""
    marker = tmp_path / "pwned"
    save_synergy_model(myosuite_model(), tmp_path / "myo")
    for name in ("pca.pkl", "ica.pkl", "scaler.pkl"):
        (tmp_path / "myo" / name).write_bytes(exploit(marker))
    trapped_metadata(tmp_path / "myo" / "metadata.npz", marker)
    out = tmp_path / "out" / "sar.npz"
    assert_one_line_error(run_cli("synergies", "import-sklearn", tmp_path / "myo", "--out", out),
                          "arbitrary code", "--trust")
    with pytest.raises(MotorlabError, match=r"source_clips as pickled object arrays.*--trust"):
        read_synergy_metadata(tmp_path / "myo" / "metadata.npz", trust=False)
    assert not marker.exists() and not out.parent.exists()


@pytest.mark.parametrize("case, fragments", [
    ("empty", ("holds no complete SAR", "missing pca.pkl, ica.pkl, normalizer.pkl for a MyoSuite 2.x",
               "or pca.pkl, ica.pkl, scaler.pkl, metadata.npz for a MyoSuite 3.0")),
    ("no_metadata", ("metadata.npz is missing", "MyoSuite 3.0 SynergyModel folder")),
    ("no_pickles", ("pca.pkl", "ica.pkl", "scaler.pkl are missing")),
    ("both", ("holds both normalizer.pkl", "keep one SAR per folder")),
])
def test_incomplete_folders_are_named_in_one_line(tmp_path, case, fragments):
    folder = tmp_path / "sar"
    folder.mkdir()
    if case != "empty":
        save_synergy_model(myosuite_model(), folder)
    if case == "no_metadata":
        (folder / "metadata.npz").unlink()
    if case == "no_pickles":
        for name in ("pca.pkl", "ica.pkl", "scaler.pkl"):
            (folder / name).unlink()
    if case == "both":
        (folder / "normalizer.pkl").write_bytes((folder / "scaler.pkl").read_bytes())
    # --trust given: the layout is checked before anything is opened, with or without it
    proc = run_here("synergies", "import-sklearn", folder, "--trust", "--out", tmp_path / "sar.npz")
    assert_one_line_error(proc, *fragments)
    assert not (tmp_path / "sar.npz").exists()


# ---- motorlab -> MyoSuite 3.0 folder --------------------------------------------------------------

@pytest.mark.parametrize("method", ["pca-ica", "pca"])
def test_fitted_sar_exports_to_what_myosuite_loads(tmp_path, method):
    sar = fit_sar(activations(), n_synergies=4, method=method, seed=1)
    result = export_sklearn(sar, tmp_path / "myo")
    assert sorted(p.name for p in (tmp_path / "myo").iterdir()) == ["ica.pkl", "metadata.npz", "pca.pkl",
                                                                     "scaler.pkl"]
    model = load_synergy_model(tmp_path / "myo")
    assert (model.n_synergies, model.n_muscles) == (4, N_MUSCLES)
    assert model.vaf == pytest.approx(sar.metadata["vaf"], rel=1e-6)  # metadata.npz keeps it as float32
    assert model.pca.explained_variance_ratio_.sum() == pytest.approx(sar.metadata["vaf"], rel=1e-12)
    z = np.random.default_rng(4).uniform(-1.2, 1.2, (2000, 4))
    assert max_diff(myosuite_decode(model, z), sar.decode(z)) < EXACT
    assert result.max_abs_error < EXACT
    x = activations(2)[:50]  # the exported estimators encode as motorlab does
    assert max_diff(model.scaler.transform(model.ica.transform(model.pca.transform(x))), sar.encode(x)) < EXACT
    # MyoSuite's GPU decode (torch, float32) builds from the same estimators
    import torch
    from myosuite.integrations.musclemimic.sar_torch_transform import SARTorchTransform

    zs = np.random.default_rng(5).uniform(-1, 1, (256, 4))
    torch_out = SARTorchTransform(model.ica, model.pca, model.scaler)(torch.tensor(zs, dtype=torch.float32))
    assert max_diff(torch_out.numpy(), np.clip(sar.decode(zs), 0, 1)) < 1e-5


@pytest.mark.parametrize("margin", [0.0, 0.25])
def test_myosuite_folder_survives_import_and_export(tmp_path, margin):
    """MyoSuite -> motorlab -> MyoSuite: the same chain, whitening, [0, 1] range and margin-widened scaler."""
    original = myosuite_model(margin)
    save_synergy_model(original, tmp_path / "myo")
    import_sklearn(tmp_path / "myo", trust=True, out=tmp_path / "sar.npz")
    export_sklearn(tmp_path / "sar.npz", tmp_path / "back")
    back = load_synergy_model(tmp_path / "back")
    z = np.random.default_rng(6).uniform(0, 1, (1000, N_SYN))
    assert max_diff(myosuite_decode(back, z), myosuite_decode(original, z)) < EXACT
    assert back.pca.whiten is True and back.scaler.feature_range == (0.0, 1.0)
    for name in ("data_min_", "data_max_", "min_", "scale_"):
        assert max_diff(getattr(back.scaler, name), getattr(original.scaler, name)) < EXACT
    assert back.source_clips == original.source_clips and back.vaf == pytest.approx(original.vaf)


def test_published_tutorial_sar_exports(tmp_path):
    """A 2.x tutorial SAR (old sklearn, ICA whiten='warn') exports to a 3.0 folder with the same chain."""
    import joblib

    sar = import_sklearn(PUBLISHED_SAR / "manipulation", trust=True, out=tmp_path / "sar.npz")
    assert sar.metadata["import_format"] == TUTORIAL
    export_sklearn(sar, tmp_path / "myo")
    model = load_synergy_model(tmp_path / "myo")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pickled with scikit-learn 1.1.2
        pca, ica, scaler = (joblib.load(PUBLISHED_SAR / "manipulation" / f)
                            for f in ("pca.pkl", "ica.pkl", "normalizer.pkl"))
    published = dataclasses.replace(model, pca=pca, ica=ica, scaler=scaler)
    z = np.random.default_rng(7).uniform(-1, 1, (1000, sar.n_synergies))
    assert max_diff(myosuite_decode(model, z), myosuite_decode(published, z)) < 1e-6
    assert max_diff(myosuite_decode(model, z), sar.decode(z)) < EXACT


def test_nmf_sar_is_refused(tmp_path):
    sar = fit_sar(activations(), n_synergies=3, method="nmf")
    with pytest.raises(MotorlabError, match="nmf SAR cannot be written"):
        export_sklearn(sar, tmp_path / "myo")
    assert not (tmp_path / "myo").exists()


def test_failed_export_leaves_nothing(tmp_path, monkeypatch):
    """A check that fails after MyoSuite wrote its files: no folder under --out, no temp folder beside it."""
    sar = fit_sar(activations(), n_synergies=4)
    original = load_synergy_model

    def off_by_a_bit(folder):
        model = original(folder)
        model.pca.mean_ = model.pca.mean_ + 1e-3
        return model

    monkeypatch.setattr(sar_extraction, "load_synergy_model", off_by_a_bit)  # export reads back through it
    with pytest.raises(MotorlabError, match="disagrees with scikit-learn's inverse chain.*nothing was written"):
        export_sklearn(sar, tmp_path / "myo")
    assert list(tmp_path.iterdir()) == []


def test_export_cli(tmp_path):
    save_sar(fit_sar(activations(), n_synergies=4), tmp_path / "sar.npz")
    (tmp_path / "empty").mkdir()
    proc = run_cli("synergies", "export-sklearn", tmp_path / "sar.npz", "--out", tmp_path / "empty")
    assert_ok(proc)
    assert "4 synergies x 12 muscles" in proc.stdout and "max abs error" in proc.stdout
    assert load_synergy_model(tmp_path / "empty").n_synergies == 4
    # the folder exists now: refused, and left as it was
    before = {p.name: p.read_bytes() for p in (tmp_path / "empty").iterdir()}
    proc = run_here("synergies", "export-sklearn", tmp_path / "sar.npz", "--out", tmp_path / "empty")
    assert_one_line_error(proc, "already exists and is not empty", "new folder")
    assert {p.name: p.read_bytes() for p in (tmp_path / "empty").iterdir()} == before


def test_cli_imports_a_myosuite_folder_and_exports_it_back(tmp_path):
    original = myosuite_model(0.25)
    save_synergy_model(original, tmp_path / "myo")
    proc = run_cli("synergies", "import-sklearn", tmp_path / "myo", "--trust", "--out", tmp_path / "sar.npz")
    assert_ok(proc)
    assert "5 synergies x 12 muscles" in proc.stdout and "decode matches scikit-learn" in proc.stdout
    assert_ok(run_cli("synergies", "export-sklearn", tmp_path / "sar.npz", "--out", tmp_path / "back"))
    z = np.random.default_rng(8).uniform(0, 1, (500, N_SYN))
    assert max_diff(myosuite_decode(load_synergy_model(tmp_path / "back"), z), myosuite_decode(original, z)) < EXACT


@pytest.mark.parametrize("case, fragments", [
    ("missing", ("does not exist",)),
    ("nmf", ("nmf SAR cannot be written", "--method pca-ica")),
    ("out_is_file", ("is a file", "new folder")),
])
def test_export_cli_mistakes_give_one_line(tmp_path, case, fragments):
    sar = tmp_path / "sar.npz"
    if case == "nmf":
        save_sar(fit_sar(activations(), n_synergies=3, method="nmf"), sar)
    elif case == "out_is_file":
        save_sar(fit_sar(activations(), n_synergies=3), sar)
    out = tmp_path / "out"
    if case == "out_is_file":
        out.write_text("notes")
    assert_one_line_error(run_here("synergies", "export-sklearn", sar, "--out", out), *fragments)
    assert (out.is_file() if case == "out_is_file" else not out.exists())
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
