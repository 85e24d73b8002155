"""RecurrentPPO (sb3-contrib, motorlab/algos/recurrent_ppo.py, `--algo recurrentppo`) through
train, evaluate, resume, export, ONNX and tune: its LSTM state is carried row by row, zeroed at
episode starts, and an explicit input/output pair of the ONNX graph."""

from __future__ import annotations

import numpy as np
import pytest

from tests.rl import algo_checks as checks

ALGO = "recurrentppo"
HYPER = {"n_steps": 64, "batch_size": 32, "n_epochs": 1,
         "policy_kwargs": {"lstm_hidden_size": 16, "net_arch": [16]}}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return checks.train(ALGO, tmp_path_factory.mktemp(ALGO) / "run", HYPER)


def test_trains_and_evaluates(run):
    checks.check_trained(run, ALGO)


def test_exported_policy_acts_as_the_sb3_model_step_after_step(run, tmp_path):
    checks.check_export_acts_as_sb3(run.path, ALGO, tmp_path / "export", steps=4)


def test_state_is_per_row_and_reset_row_zeroes_it(run):
    from motorlab.policies import load_run_policy

    policy = load_run_policy(run.path)
    obs = checks.observations(3)
    policy.reset(3)
    first = policy.act(obs)
    second = policy.act(obs)
    assert not np.array_equal(first, second)  # the state changed the action for the same observation
    policy.reset_row(1)
    third = policy.act(obs)
    np.testing.assert_array_equal(third[1], first[1])  # row 1 starts over: as at its first step
    assert not np.array_equal(third[0], first[0])
    policy.reset(3)
    np.testing.assert_array_equal(policy.act(obs), first)


def test_onnx_carries_the_lstm_state(run, tmp_path):
    sidecar = checks.check_onnx(run.path, tmp_path / "onnx", steps=5)
    names = [i["name"] for i in sidecar["inputs"]], [o["name"] for o in sidecar["outputs"]]
    assert names == (["obs", "lstm_h", "lstm_c"], ["action", "next_lstm_h", "next_lstm_c"])
    assert sidecar["inputs"][1]["shape"] == [1, "batch", 16]
    assert "zeros at an episode's start" in sidecar["inputs"][1]["description"]


def test_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    checks.check_resume(ALGO, tmp_path / "run", HYPER, monkeypatch, checkpoint_every=128)


def test_tunes(tmp_path):
    checks.check_tune(ALGO, tmp_path / "tune", "--set n_steps=64 --set batch_size=32 --set n_epochs=1 "
                      "--set 'policy_kwargs={\"lstm_hidden_size\":16,\"net_arch\":[16]}'")
