"""The synergy analyses through the CLI: cross-validated VAF with its criteria, fit choosing N by a named
criterion (heatmap labelled with muscle names), compare against the shuffled null."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motorlab.runs import atomic_write_npz
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli
from tests.synergies.ground_truth import ground_truth


def write_truth(path, seed=0, episodes=20):
    g = ground_truth(seed=seed, episodes=episodes)
    n = g.activations.shape[1]
    atomic_write_npz(path, activations=g.activations, names=np.array(g.names), episode=g.episode,
                     signal=np.array("act"), low=np.zeros(n), high=np.ones(n),
                     metadata=np.array(json.dumps({"env_id": "ground-truth", "signal": "act"})))
    return g


@pytest.fixture(scope="module")
def truth_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("truth") / "activations.npz"
    return path, write_truth(path)


def test_vaf_cross_validated_names_its_definition_and_every_criterion(truth_file, tmp_path):
    path, _ = truth_file
    out = tmp_path / "vaf"
    assert_ok(run_cli("synergies", "vaf", path, "--method", "nmf", "--cv", "4", "--max-n", "7", "--threshold", "0.9",
                      "--out", out))
    s = read_summary(out)
    assert s["cv_folds"] == 4 and s["vaf_definition"] == "uncentred"
    assert (s["n_for_threshold"], s["n_by_muscle_vaf"], s["n_by_elbow"]) == (4, 4, 4)
    assert len(s["vaf"]) == len(s["vaf_std"]) == 7 and max(s["vaf_std"]) > 0
    assert s["names"][:2] == ["m00", "m01"] and len(s["muscle_vaf"]) == 7 and len(s["muscle_vaf"][0]) == 12
    assert (out / "vaf.png").is_file()


def test_fit_says_which_criterion_chose_n_and_names_the_heatmap(truth_file, tmp_path):
    from motorlab.synergies.sar import load_sar
    from motorlab.synergies.similarity import match
    from motorlab.synergies.vectors import vectors_of

    path, g = truth_file
    out = tmp_path / "fit"
    assert_ok(run_cli("synergies", "fit", path, "--method", "nmf", "--muscle-vaf", "0.75", "--cv", "4",
                      "--max-n", "7", "--out", out))
    s = read_summary(out)
    assert s["n_synergies"] == 4 and "every muscle's held-out VAF" in s["chosen_by"] and s["names"] == g.names
    sar = load_sar(out / "sar.npz")
    assert sar.metadata["names"] == g.names  # stored in the synergy file
    assert min(match(g.synergies, vectors_of(sar).normalized).similarity) >= 0.95
    for figure in ("heatmap.png", "coefficients.png", "vaf.png"):
        assert (out / figure).is_file(), figure
    proc = run_cli("synergies", "fit", path, "--n", "3", "--elbow", "--out", tmp_path / "both")
    assert_one_line_error(proc, "exactly one way to choose N", "--n-synergies", "--elbow")
    assert not (tmp_path / "both").exists()


def test_compare_matches_two_fits_above_chance_and_refuses_other_muscles(truth_file, tmp_path):
    path, _ = truth_file
    other = tmp_path / "other.npz"
    write_truth(other, seed=0, episodes=12)  # the same synergies, other episodes
    for name, source in (("fa", path), ("fb", other)):
        assert_ok(run_cli("synergies", "fit", source, "--method", "nmf", "--n", "4", "--out", tmp_path / name))
    out = tmp_path / "cmp"
    assert_ok(run_cli("synergies", "compare", tmp_path / "fa", tmp_path / "fb", "--surrogates", "20",
                      "--workers", "2", "--out", out))
    s = read_summary(out)
    assert s["similarity_mean"] > 0.95 and s["pairs_above_chance"] == 4 and s["chance_pair_p95"] < 0.9
    assert not s["absolute"] and (out / "similarity.png").is_file()
    # a set over other muscles: one line naming the names that differ
    g = ground_truth(seed=0, episodes=8)
    renamed = tmp_path / "renamed.npz"
    n = g.activations.shape[1]
    atomic_write_npz(renamed, activations=g.activations, names=np.array([*g.names[:-1], "biceps"]), episode=g.episode,
                     signal=np.array("act"), low=np.zeros(n), high=np.ones(n), metadata=np.array("{}"))
    assert_ok(run_cli("synergies", "fit", renamed, "--method", "nmf", "--n", "4", "--out", tmp_path / "fr"))
    proc = run_cli("synergies", "compare", tmp_path / "fa", tmp_path / "fr", "--out", tmp_path / "bad")
    assert_one_line_error(proc, "only in A: m11", "only in B: biceps")
    assert not (tmp_path / "bad").exists()


@pytest.mark.parametrize("command", ["vaf", "fit"])
def test_nmf_refuses_a_negative_value_anywhere_before_any_fit(tmp_path, command):
    g = ground_truth(seed=0, episodes=6)
    x = g.activations.copy()
    x[-1, 3] = -0.5  # the very last sample
    n = x.shape[1]
    path = tmp_path / "neg.npz"
    atomic_write_npz(path, activations=x, names=np.array(g.names), episode=g.episode, signal=np.array("act"),
                     low=np.zeros(n), high=np.ones(n), metadata=np.array("{}"))
    extra = ["--muscle-vaf", "0.75"] if command == "fit" else []
    proc = run_cli("synergies", command, path, "--method", "nmf", "--cv", "3", *extra, "--out", tmp_path / "out")
    assert_one_line_error(proc, "non-negative activations", "-0.5")
    assert not (tmp_path / "out").exists()
