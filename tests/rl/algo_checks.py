"""What every algorithm of motorlab/algos/ must do, on a tiny budget: train, evaluate, resume,
export (pickle-free, acting as the SB3 model does), ONNX (onnxruntime equal to torch) and tune.
Each algorithm's test file calls these with its name and small hyperparameters."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import motorlab
from motorlab import algos

ENV = "Pendulum-v1"  # 200-step episodes, 3 observations, one Box action: seconds per run
STEPS = 300


def train(algo: str, out: Path, hyperparams: dict[str, Any], **settings: Any):
    return motorlab.train(ENV, algo, STEPS, out=out, progress=False, hyperparams=hyperparams, eval_every=200,
                          **settings)


def check_trained(run, algo: str) -> None:
    summary = run.summary
    assert summary["algo"] == algo and summary["timesteps"] >= STEPS
    assert math.isfinite(summary["eval_return_mean"])
    meta = json.loads((run.path / "policy.json").read_text())
    assert meta["algo"] == algo and meta["policy_class"] in algos.get(algo).networks
    result = motorlab.evaluate(run, episodes=2, progress=False, out=run.path.parent / f"{algo}-eval")
    assert result.summary["episodes"] == 2 and result.summary["episode_lengths"] == [200, 200]
    assert math.isfinite(result.summary["return_mean"])


def observations(n: int, seed: int = 0) -> np.ndarray:
    """Pendulum observations: cos, sin, angular velocity."""
    rng = np.random.default_rng(seed)
    theta, speed = rng.uniform(-np.pi, np.pi, n), rng.uniform(-8, 8, n)
    return np.stack([np.cos(theta), np.sin(theta), speed], axis=1).astype(np.float32)


def check_export_acts_as_sb3(run_dir: Path, algo: str, out: Path, steps: int = 1) -> None:
    """export_run writes a pickle-free folder whose policy acts as SB3's model.zip does, step after
    step (a recurrent policy's state carried by both)."""
    from safetensors.numpy import load_file

    from motorlab.export import export_run
    from motorlab.policies import load_run_policy

    export_run(run_dir, out)
    assert (out / "policy.safetensors").is_file() and not (out / "model.zip").exists()
    assert not list(out.rglob("*.pkl")) and not list(out.rglob("*.zip"))
    assert load_file(str(out / "policy.safetensors"))  # plain tensors, read without unpickling
    model = algos.get(algo).sb3_class().load(run_dir / "model.zip", device="cpu")
    policy = load_run_policy(out)
    batch = 5
    policy.reset(batch)
    state = None
    for t in range(steps):
        obs = observations(batch, seed=t)
        expected, state = model.predict(obs, state=state, deterministic=True)
        np.testing.assert_array_equal(policy.act(obs), expected, err_msg=f"step {t}")


def check_onnx(run_dir: Path, out: Path, steps: int = 1) -> dict:
    """export_onnx, then onnxruntime on new observations equals the torch policy to 1e-5, over
    `steps` steps with the graph's recurrent outputs fed back as its inputs."""
    ort = pytest.importorskip("onnxruntime")
    from motorlab.deploy_onnx import TOLERANCE, export_onnx
    from motorlab.policies import load_run_policy

    summary = export_onnx(run_dir, out)
    assert summary["max_abs_error"] <= TOLERANCE
    session = ort.InferenceSession(str(out / "policy.onnx"), providers=["CPUExecutionProvider"])
    sidecar = json.loads((out / "policy.onnx.json").read_text())
    states = [i for i in sidecar["inputs"] if i["name"] not in ("obs", "obs_stack")]
    batch = 4
    carried = {s["name"]: np.zeros([batch if d == "batch" else d for d in s["shape"]], np.float32) for s in states}
    policy = load_run_policy(run_dir)
    policy.reset(batch)
    for t in range(steps):
        obs = observations(batch, seed=100 + t)
        results = session.run(None, {"obs": obs, **carried})
        np.testing.assert_allclose(results[0], policy.act(obs), atol=1e-5, err_msg=f"step {t}")
        carried = {s["name"]: r for s, r in zip(states, results[1:])}
    return sidecar


def check_resume(algo: str, out: Path, hyperparams: dict[str, Any], monkeypatch, checkpoint_every: int) -> None:
    """A run stopped after its checkpoints (before it saved its policy) resumes from the last one:
    the step count goes on from the checkpoint's, to the same budget."""
    import motorlab.rl.sb3 as sb3
    from motorlab.kinds.train import TRAIN
    from motorlab.rl.config import resolve
    from motorlab.runs import read_config

    class Stopped(Exception):
        pass

    def stop(*args):
        raise Stopped

    with monkeypatch.context() as m:
        m.setattr(sb3, "_save_model", stop)  # dies as a killed process would: after checkpoints, before the end
        with pytest.raises(Stopped):
            train(algo, out, hyperparams, checkpoint_every=checkpoint_every)
    latest = json.loads((out / "checkpoint" / "latest.json").read_text())
    assert 0 < latest["steps"] < STEPS
    summary = TRAIN.perform(resolve(read_config(out)), out, resume=True).keys()
    assert summary["resumed_from"] == latest["steps"]
    assert summary["timesteps"] >= STEPS and summary["budget"] == STEPS
    assert not (out / "checkpoint").exists() and (out / "policy.safetensors").is_file()


def check_tune(algo: str, out: Path, flags: str) -> None:
    """Two trials of one seed, each a training of this algorithm, with finite returns."""
    tune = motorlab.tune(f"train {ENV} --algo {algo} --timesteps {STEPS} --eval-every 200 {flags}",
                         space={"lr": "loguniform:1e-4,1e-3"}, trials=2, seeds=1, objective="final_return",
                         out=out, fresh_seeds=0, prune_startup=5)
    trials = tune.trials
    assert len(trials) == 2
    assert all(t["state"].lower() == "complete" and math.isfinite(float(t["value"])) for t in trials), trials
    for number in range(2):
        assert json.loads((out / "trials" / str(number) / "seed0" / "summary.json").read_text())["algo"] == algo
