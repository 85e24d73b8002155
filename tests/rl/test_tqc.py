"""TQC (sb3-contrib, motorlab/algos/tqc.py) through train, evaluate, resume, export, ONNX and tune."""

from __future__ import annotations

import pytest

from tests.rl import algo_checks as checks

ALGO = "tqc"
HYPER = {"learning_starts": 100, "batch_size": 32, "policy_kwargs": {"net_arch": [32, 32], "n_critics": 2}}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return checks.train(ALGO, tmp_path_factory.mktemp(ALGO) / "run", HYPER)


def test_trains_and_evaluates(run):
    checks.check_trained(run, ALGO)


def test_exported_policy_acts_as_the_sb3_model(run, tmp_path):
    checks.check_export_acts_as_sb3(run.path, ALGO, tmp_path / "export")


def test_onnx_equals_torch(run, tmp_path):
    sidecar = checks.check_onnx(run.path, tmp_path / "onnx")
    assert [i["name"] for i in sidecar["inputs"]] == ["obs"] and sidecar["algo"] == ALGO


def test_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    checks.check_resume(ALGO, tmp_path / "run", HYPER, monkeypatch, checkpoint_every=200)


def test_tunes(tmp_path):
    checks.check_tune(ALGO, tmp_path / "tune", "--set learning_starts=100 --set batch_size=32 "
                      "--set 'policy_kwargs={\"net_arch\":[32,32]}'")
