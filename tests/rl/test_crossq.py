"""CrossQ (sb3-contrib, motorlab/algos/crossq.py) through train, evaluate, resume, export, ONNX
and tune; its batch-renormalization statistics travel with the weights."""

from __future__ import annotations

import pytest

from tests.rl import algo_checks as checks

ALGO = "crossq"
HYPER = {"learning_starts": 100, "batch_size": 32, "policy_kwargs": {"net_arch": [32, 32]}}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return checks.train(ALGO, tmp_path_factory.mktemp(ALGO) / "run", HYPER)


def test_trains_and_evaluates(run):
    checks.check_trained(run, ALGO)


def test_exported_policy_acts_as_the_sb3_model(run, tmp_path):
    from safetensors.numpy import load_file

    checks.check_export_acts_as_sb3(run.path, ALGO, tmp_path / "export")
    tensors = load_file(str(tmp_path / "export" / "policy.safetensors"))
    running = [v for k, v in tensors.items() if k.startswith("policy.actor.") and k.endswith(".ra_mean")]
    assert running and any(v.any() for v in running)  # the actor's batch-renormalization statistics, as trained


def test_onnx_equals_torch(run, tmp_path):
    checks.check_onnx(run.path, tmp_path / "onnx")


def test_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    checks.check_resume(ALGO, tmp_path / "run", HYPER, monkeypatch, checkpoint_every=200)


def test_tunes(tmp_path):
    checks.check_tune(ALGO, tmp_path / "tune", "--set learning_starts=100 --set batch_size=32 "
                      "--set 'policy_kwargs={\"net_arch\":[32,32]}'")


def test_refuses_her_and_dict_observations():
    from motorlab import algos
    from motorlab.errors import MotorlabError
    from motorlab.rl.config import TrainConfig

    with pytest.raises(MotorlabError, match="--her .* CrossQ .*--algo sac"):
        TrainConfig(algo=ALGO, her=True)
    with pytest.raises(MotorlabError, match="no policy for Dict observations"):
        algos.get(ALGO).policy(dict_obs=True, env_id="PointMaze_UMaze-v3")
