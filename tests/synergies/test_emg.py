"""`motorlab synergies import-emg`: raw EMG to normalized envelopes (motorlab.synergies.emg). Synthetic EMG
made from known synergies (carrier noise modulated by each muscle's activation) gives the synergies back;
every bad input is one line naming the problem; the file it writes is an activations.npz that `synergies
vaf` and `fit` read."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from motorlab.errors import MotorlabError
from motorlab.kinds.import_emg import IMPORT_EMG
from motorlab.kinds.synergies import VAF
from motorlab.synergies.emg import EnvelopeFilters, import_emg
from motorlab.synergies.sar import fit_sar, load_sar
from motorlab.synergy_runs.activations import load_activations
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli, run_here, run_kind

RATE = 2000.0
MUSCLES = ("TA", "SOL", "GM", "GL", "PL", "VL", "VM", "RF", "BF", "ST", "GMax", "GMed")
K = 4  # true synergies
TRIALS, SECONDS = 6, 4.0
GEN = settings(max_examples=25, deadline=None, derandomize=True, database=None,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def ground_truth(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Activations from K known non-negative synergies with smooth known coefficients: (activations
    (S, M) in [0, 1] with each muscle's maximum 1, as the import normalizes, each sample's trial (S,),
    the synergies (K, M) in those units)."""
    rng = np.random.default_rng(seed)
    w = 0.25 * rng.uniform(0, 1, (K, len(MUSCLES))) * (rng.random((K, len(MUSCLES))) < 0.3)
    for k in range(K):
        w[k, 3 * k:3 * k + 3] += rng.uniform(0.6, 1.0, 3)  # each synergy has its own group of 3 muscles
    t = np.arange(int(SECONDS * RATE)) / RATE
    coef, trial = [], []
    for i in range(TRIALS):
        # each synergy's coefficient: a sum of Gaussian bursts (0.1-0.3 s wide), slow next to the 6 Hz envelope
        c = np.zeros((len(t), K))
        for k in range(K):
            for mu, sd, a in zip(rng.uniform(0.3, SECONDS - 0.3, 3), rng.uniform(0.1, 0.3, 3), rng.uniform(0.3, 1, 3)):
                c[:, k] += a * np.exp(-0.5 * ((t - mu) / sd) ** 2)
        coef.append(c)
        trial.append(np.full(len(t), i))
    acts = np.concatenate(coef) @ w
    peak = acts.max(axis=0)
    return acts / peak, np.concatenate(trial), w / peak


def synthetic_emg(acts: np.ndarray, seed: int = 1) -> np.ndarray:
    """Raw EMG: carrier noise modulated by each muscle's activation (motorlab.synergies.synthetic)."""
    from motorlab.synergies.synthetic import synthetic_emg as made

    return made(acts, RATE, seed)


def write_csv(path: Path, header: list[str], rows) -> Path:
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def emg_file(path: Path, emg: np.ndarray, trial: np.ndarray | None = None, names=MUSCLES) -> Path:
    """A CSV as a user exports it: the header, then `trial` (if given) and each muscle's raw EMG."""
    import pandas as pd

    columns = {} if trial is None else {"trial": trial}
    columns.update({n: emg[:, i] for i, n in enumerate(names)})
    pd.DataFrame(columns).to_csv(path, index=False, float_format="%.6g")
    return path


def matched_cosines(found: np.ndarray, true: np.ndarray) -> np.ndarray:
    """The cosine similarity of each true synergy with the found one optimally matched to it."""
    a = found / np.linalg.norm(found, axis=1, keepdims=True)
    b = true / np.linalg.norm(true, axis=1, keepdims=True)
    cos = a @ b.T
    rows, cols = linear_sum_assignment(-cos)
    return cos[rows, cols]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The synthetic recording's file, its true activations, trials and synergies."""
    acts, trial, w = ground_truth()
    path = emg_file(tmp_path_factory.mktemp("emg") / "walking.csv", synthetic_emg(acts), trial)
    return path, acts, trial, w


@pytest.fixture(scope="module")
def imported(recorded):
    return import_emg(recorded[0], RATE)


@pytest.mark.fast  # make test-fast: the workflow's ground truth
def test_importing_synthetic_emg_recovers_the_synergies(recorded, imported):
    path, acts, trial, w = recorded
    env = imported
    step = int(RATE / 100)  # the default --downsample 100 Hz picks every 20th sample of each trial
    assert env.rate == 100 and env.names == MUSCLES and env.trials == tuple(range(TRIALS))
    assert env.activations.shape == (TRIALS * int(SECONDS * 100), len(MUSCLES))
    assert env.activations.min() >= 0 and env.activations.max() == pytest.approx(1.0)
    assert np.array_equal(env.episode, np.repeat(np.arange(TRIALS), int(SECONDS * 100)))
    # each envelope follows its muscle's true activation
    true = np.concatenate([acts[trial == i][::step] for i in range(TRIALS)])
    r = [np.corrcoef(env.activations[:, m], true[:, m])[0, 1] for m in range(len(MUSCLES))]
    assert min(r) > 0.9, r
    sar = fit_sar(env.activations, n_synergies=K, method="nmf", seed=0)
    cos = matched_cosines(sar.arrays["nmf_components"], w)
    assert cos.min() >= 0.9, cos


def test_filtering_stays_within_each_trial(recorded, tmp_path):
    """A trial's envelope is the same whether its neighbours are in the file or not (before normalization):
    no filter runs across a trial boundary."""
    path, acts, trial, _ = recorded
    emg = synthetic_emg(acts)[trial < 2]
    emg[trial[trial < 2] == 0] *= 20  # a loud trial beside a quiet one
    both = import_emg(emg_file(tmp_path / "both.csv", emg, trial[trial < 2]), RATE)
    alone = [import_emg(emg_file(tmp_path / f"{i}.csv", emg[trial[trial < 2] == i]), RATE) for i in (0, 1)]
    for i, one in enumerate(alone):
        assert np.allclose(both.activations[both.episode == i] * both.scale, one.activations * one.scale,
                           rtol=1e-6, atol=1e-9)


def test_mvc_normalization(recorded, imported, tmp_path):
    """Dividing by MVC values equal to the maxima gives the default normalization; by half of them, the
    values above the MVC are clipped to 1. Their header may list the muscles in another order."""
    names = list(reversed(MUSCLES))
    scale = dict(zip(MUSCLES, imported.scale))
    same = write_csv(tmp_path / "mvc.csv", names, [[repr(float(scale[n])) for n in names]])
    by_mvc = import_emg(recorded[0], RATE, mvc=same)
    assert by_mvc.normalization == "mvc" and np.allclose(by_mvc.activations, imported.activations)
    half = write_csv(tmp_path / "half.csv", names, [[repr(float(scale[n]) / 2) for n in names]])
    clipped = import_emg(recorded[0], RATE, mvc=half)
    assert clipped.clipped > 0 and clipped.activations.max() == 1.0 and clipped.activations.min() >= 0


@given(trials=st.integers(1, 3), muscles=st.integers(1, 5), length=st.integers(200, 600),
       downsample=st.sampled_from([None, 100.0, 333.0, 1000.0]), seed=st.integers(0, 2**16))
@GEN
def test_any_shape_gives_envelopes_in_the_unit_interval(tmp_path_factory, trials, muscles, length, downsample,
                                                        seed):
    rng = np.random.default_rng(seed)
    names = [f"m{i}" for i in range(muscles)]
    trial = np.repeat(np.arange(trials) * 7 + 3, length)  # labels need not count from 0
    emg = rng.normal(0, 1, (len(trial), muscles)) * rng.uniform(0.1, 5, muscles)
    path = emg_file(tmp_path_factory.getbasetemp() / "shape.csv", emg, trial, names)
    env = import_emg(path, RATE, EnvelopeFilters(downsample=downsample))
    per_trial = length if downsample is None else int(math.floor((length - 1) / RATE * downsample)) + 1
    assert env.activations.shape == (trials * per_trial, muscles) and env.activations.dtype == np.float64
    assert env.activations.min() >= 0 and np.allclose(env.activations.max(axis=0), 1.0)
    assert env.names == tuple(names) and env.trials == tuple(np.arange(trials) * 7 + 3)
    assert np.array_equal(env.episode, np.repeat(np.arange(trials), per_trial))


def test_time_and_trial_columns_are_not_muscles(tmp_path):
    """Exports often begin with time stamps, and name columns in capitals: `Time` is ignored, `Trial` is the trial."""
    rng = np.random.default_rng(0)
    rows = [[f"{i / RATE:.4f}", str(i // 300), *(f"{v:.4f}" for v in rng.normal(0, 1, 2))] for i in range(900)]
    env = import_emg(write_csv(tmp_path / "export.csv", ["Time", "Trial", "TA", "SOL"], rows), RATE)
    assert env.names == ("TA", "SOL") and env.trials == (0, 1, 2) and env.activations.shape == (3 * 15, 2)
    mvc = write_csv(tmp_path / "mvc.csv", ["time", "SOL", "TA"], [["0", "1", "1"]])
    assert import_emg(tmp_path / "export.csv", RATE, mvc=mvc).normalization == "mvc"


# ---- bad input: one line naming the problem ------------------------------------------------------

def _valid(rng: np.random.Generator, rows: int = 300) -> tuple[list[str], list[list[str]]]:
    names = ["trial", "TA", "SOL", "GM"]
    body = [[str(i * 2 // rows)] + [f"{v:.5f}" for v in rng.normal(0, 1, 3)] for i in range(rows)]
    return names, body


def _error(path: Path, rate: float = RATE, **kwargs) -> str:
    with pytest.raises(MotorlabError) as e:
        import_emg(path, rate, **kwargs)
    text = str(e.value)
    assert "\n" not in text and text.endswith("."), text
    return text


BAD = ["nan", "empty", "text", "inf", "constant", "duplicate", "blank name", "no header", "split trial",
       "fractional trial"]


@given(bad=st.sampled_from(BAD), row=st.integers(0, 299), column=st.integers(1, 3), seed=st.integers(0, 2**16))
@GEN
def test_each_bad_cell_or_column_is_one_line_naming_it(tmp_path_factory, bad, row, column, seed):
    names, body = _valid(np.random.default_rng(seed))
    name = names[column]
    expect = [name]
    if bad in ("nan", "empty", "text", "inf"):
        body[row][column] = {"nan": "NaN", "empty": "", "text": "1.2mV", "inf": "inf"}[bad]
        expect += [f"row {row + 1} below the header", {"nan": "missing", "empty": "missing", "text": "'1.2mV'",
                                                       "inf": "infinite"}[bad]]
    elif bad == "constant":
        for line in body:
            line[column] = "0.25"
        expect += ["constant", "0.25", "remove the column"]
    elif bad == "duplicate":
        names[column] = names[column % 3 + 1]
        expect = [repr(names[column]), "more than once"]
    elif bad == "blank name":
        names[column] = " "
        expect = [f"column {column + 1} of the header has no name"]
    elif bad == "no header":
        body.insert(0, ["0", "1.0", "2.0", "3.0"])
        names = ["0", "0.5", "0.25", "0.125"]
        expect = ["no header row"]
    elif bad == "split trial":
        for line in body[-10:]:
            line[0] = "0"  # trial 0's rows again after trial 1's
        expect = ["trial 0's rows are not together", f"row {len(body) - 10 + 1} below the header", "sort the rows"]
    else:
        body[row][0] = "0.5"
        expect = ["'trial'", "0.5", f"row {row + 1} below the header", "whole number"]
    text = _error(write_csv(tmp_path_factory.getbasetemp() / "bad.csv", names, body))
    for fragment in expect:
        assert fragment in text, (fragment, text)


def test_bad_files_and_settings_are_one_line_each(tmp_path):
    rng = np.random.default_rng(0)
    names, body = _valid(rng)
    good = write_csv(tmp_path / "good.csv", names, body)
    assert "does not exist" in _error(tmp_path / "nope.csv")
    assert "is a folder" in _error(tmp_path)
    (tmp_path / "empty.csv").write_text("")
    assert "is empty" in _error(tmp_path / "empty.csv")
    (tmp_path / "binary.csv").write_bytes(b"\xff\xfe\x00\x81garbage")
    assert "cannot be read as a CSV text file" in _error(tmp_path / "binary.csv")
    assert "no rows of samples" in _error(write_csv(tmp_path / "header.csv", names, []))
    assert "one value per header column" in _error(write_csv(tmp_path / "ragged.csv", names, [*body, ["0", "1"] * 3]))
    assert "no muscle columns" in _error(write_csv(tmp_path / "trial.csv", ["trial"], [["0"], ["0"]]))
    # too few samples for the filters: says how many a trial needs
    short = write_csv(tmp_path / "short.csv", names, [["0", *line[1:]] for line in body[:20]])
    text = _error(short)
    assert "the recording has 20 samples" in text and "need at least" in text
    text = _error(write_csv(tmp_path / "short_trial.csv", names, [*body, *[["9", *line[1:]] for line in body[:5]]]))
    assert "trial 9 has 5 samples" in text
    # a rate the band cannot fit under its Nyquist frequency: the rate needed, or the --band to give
    text = _error(good, rate=800)
    assert "twice the band's upper edge (450 Hz)" in text and "above 900 Hz" in text and "--band 20,360" in text
    assert "record at a higher rate" in _error(good, rate=40)
    assert "--lowpass" in _error(good, filters=EnvelopeFilters(band=(20, 100), lowpass=300), rate=500)
    assert "--downsample 10 Hz" in _error(good, filters=EnvelopeFilters(downsample=10))
    assert "0 < LOW < HIGH" in _error(good, filters=EnvelopeFilters(band=(450, 20)))
    # MVC files: other names (named), a value not above 0 (named), not one row
    text = _error(good, mvc=write_csv(tmp_path / "mvc1.csv", ["TA", "SOL", "Gastroc"], [["1", "1", "1"]]))
    assert "missing GM" in text and "not in the EMG Gastroc" in text
    text = _error(good, mvc=write_csv(tmp_path / "mvc2.csv", ["GM", "SOL", "TA"], [["1", "0", "2"]]))
    assert "'SOL' is 0" in text and "above 0" in text
    assert "give exactly one" in _error(good, mvc=write_csv(tmp_path / "mvc3.csv", ["TA", "SOL", "GM"],
                                                            [["1", "1", "1"]] * 2))


def test_cli_refuses_bad_input_in_one_line_and_writes_nothing(recorded, tmp_path):
    names, body = _valid(np.random.default_rng(0))
    body[41][2] = "nan"
    out = tmp_path / "out"
    proc = run_cli("synergies", "import-emg", write_csv(tmp_path / "gap.csv", names, body), "--rate", "2000",
                   "--out", out)
    assert_one_line_error(proc, "'SOL'", "missing value", "row 42 below the header")
    assert not out.exists()
    proc = run_cli("synergies", "import-emg", recorded[0], "--rate", "600", "--out", out)
    assert_one_line_error(proc, "--rate 600 Hz", "450 Hz", "--band 20,270")
    assert not out.exists()
    proc = run_here("synergies", "import-emg", recorded[0], "--rate", "2000", "--band", "450,20", "--out", out)
    assert_one_line_error(proc, "--band")
    proc = run_here("synergies", "import-emg", recorded[0], "--rate", "2000", "--mvc", tmp_path / "none.csv",
                    "--out", out)
    assert_one_line_error(proc, "none.csv does not exist")
    assert not out.exists()


# ---- the file it writes ----------------------------------------------------------------------------

def test_the_activations_file_round_trips_and_vaf_reads_it(recorded, imported, tmp_path):
    s = run_kind(IMPORT_EMG, tmp_path / "emg", file=str(recorded[0]), rate=RATE)
    acts, meta = load_activations(Path(s["run_dir"]))
    assert np.array_equal(acts, imported.activations)
    assert meta["names"] == list(MUSCLES) and np.array_equal(meta["episode"], imported.episode)
    assert meta["signal"] == "emg" and np.all(meta["low"] == 0) and np.all(meta["high"] == 1)
    assert meta["filters"]["band_hz"] == [20.0, 450.0] and meta["filters"]["lowpass_hz"] == 6.0
    assert meta["normalization"] == "max" and meta["recorded_rate"] == RATE and meta["rate"] == 100
    assert meta["source_file"] == str(recorded[0].resolve())
    assert s["names"] == list(MUSCLES) and s["trials"] == TRIALS and s["samples"] == len(acts)
    vaf = run_kind(VAF, tmp_path / "vaf", activations=s["run_dir"], method="nmf", max_n=K + 1, threshold=0.9)
    assert vaf["signal"] == "emg" and len(vaf["vaf"]) == K + 1 and vaf["vaf"][K - 1] > 0.9


def test_cli_import_then_fit(recorded, tmp_path):
    out, fit = tmp_path / "emg", tmp_path / "fit"
    proc = run_cli("synergies", "import-emg", recorded[0], "--rate", "2000", "--out", out)
    assert_ok(proc)
    assert f"{TRIALS} trials" in proc.stdout and "12 muscles" in proc.stdout
    assert read_summary(out)["n_muscles"] == len(MUSCLES)
    proc = run_cli("synergies", "fit", out / "activations.npz", "--n", "4", "--method", "nmf", "--out", fit)
    assert_ok(proc)
    sar = load_sar(fit / "sar.npz")
    assert sar.n_synergies == K and sar.n_muscles == len(MUSCLES) and sar.metadata["signal"] == "emg"
    assert matched_cosines(sar.arrays["nmf_components"], recorded[3]).min() >= 0.9
