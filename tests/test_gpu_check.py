"""scripts/gpu-check.sh rehearsed on the CPU (--device cpu --quick): every part runs through motorlab's
CLI and the JSON has the shape a GPU run's will have; without CUDA, --device cuda is one clear line."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "gpu-check.sh"


def test_a_cpu_rehearsal_runs_every_part_and_records_its_rates(tmp_path):
    proc = subprocess.run([str(SCRIPT), "--device", "cpu", "--quick", "--results", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    printed = json.loads(proc.stdout)
    recorded = json.loads((tmp_path / "gpu_check-quick.json").read_text())
    assert printed == recorded
    assert recorded["device"] == "cpu" and recorded["quick"] is True
    sac = recorded["sac"]["cpu"]
    assert sac["updates"] > 0 and sac["updates_per_second"] > 0 and sac["env_steps_per_second"] > 0
    assert sac["env_steps"] >= recorded["sizes"]["sac_steps"]["cpu"]
    assert recorded["sac"]["updates_per_second_device_over_cpu"] is None  # nothing compared on a CPU-only run
    model = recorded["forward_model"]["cpu"]
    assert model["fit_train_seconds"] > 0 and model["plan_ms_per_env_step"] > 0 and model["epochs"] > 0
    study = recorded["study"]
    assert study["recipe"] == "sar-hand-reference" and study["scale"] == "1/5000"
    assert set(study["step_seconds"]) >= {"play", "collect", "fit", "sar-rl", "rl-e2e", "zeroshot"}
    assert {"sar-rl.success_rate", "rl-e2e.success_rate"} <= set(study["findings"])
    assert all(0.0 <= v <= 1.0 for v in study["findings"].values())
    assert recorded["argv"][:2] == ["--device", "cpu"] and recorded["date"]
    hours = recorded["projection"]["cpu"]  # the full protocol at the measured rate: more machines, less time
    assert recorded["projection"]["recipe"] == "sar-hand-reference" and list(hours) == ["1", "2", "5"]
    assert hours["1"] > hours["2"] > hours["5"] > 0


@pytest.mark.fast
def test_cuda_without_a_gpu_is_one_clear_line(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA: the refusal cannot happen here")
    proc = subprocess.run([str(SCRIPT), "--device", "cuda", "--results", str(tmp_path)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode != 0
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "no CUDA device" in lines[0] and "--device cpu --quick" in lines[0]
    assert not list(tmp_path.iterdir())  # nothing recorded
