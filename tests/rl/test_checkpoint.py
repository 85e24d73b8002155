"""Checkpoints and `motorlab train --resume`: a training process killed with SIGKILL continues
from its last checkpoint to the same budget, with an intact metrics.csv and summary.json."""

from __future__ import annotations

import csv
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from safetensors.numpy import load_file

from motorlab.errors import MotorlabError
from motorlab.rl.monitor import METRIC_FIELDS
from motorlab.runs import MetricsWriter
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_cli, run_here


def _train_and_kill(out: Path, args: list[str], at_least: int) -> int:
    """Start `motorlab train`, SIGKILL it once a checkpoint at >= `at_least` steps exists."""
    proc = subprocess.Popen([sys.executable, "-m", "motorlab", "train", ENV_ID, *args, "--no-progress", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    latest = out / "checkpoint" / "latest.json"
    deadline = time.monotonic() + 180
    steps = 0
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            steps = json.loads(latest.read_text())["steps"]
        except (OSError, ValueError):
            steps = 0
        if steps >= at_least:
            break
        time.sleep(0.05)
    assert proc.poll() is None, f"training ended before the kill: {proc.communicate()}"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (out / "summary.json").exists()  # visibly unfinished
    return steps


def _metrics_rows(run: Path) -> list[dict]:
    text = (run / "metrics.csv").read_text()
    assert text.endswith("\n")
    rows = list(csv.DictReader(text.splitlines()))
    assert all(None not in r and len(r) == len(METRIC_FIELDS) for r in rows)  # no torn row
    return rows


def test_ppo_killed_with_sigkill_resumes_to_the_same_budget(tmp_path):
    out = tmp_path / "ppo"
    args = ["--algo", "ppo", "--timesteps", "4096", "--set", "n_steps=256", "--set", "batch_size=64",
            "--checkpoint-every", "512"]
    at = _train_and_kill(out, args, 1024)
    proc = run_cli("train", "--resume", out, "--no-progress")
    assert_ok(proc)
    assert f"resumed at {at:,} steps" in proc.stdout
    summary = read_summary(out)
    assert summary["resumed_from"] == at and summary["timesteps"] == 4096
    rows = _metrics_rows(out)
    steps = [float(r["timesteps"]) for r in rows]
    assert steps == sorted(steps)  # rows past the checkpoint were dropped, not repeated
    assert len({tuple(r.values()) for r in rows}) == len(rows)
    evals = [s for s, r in zip(steps, rows) if r["eval_return_mean"]]
    assert len(evals) == len(set(evals)) and max(evals) == 4096
    assert not (out / "checkpoint").exists()  # finished: nothing left to resume
    assert (out / "policy.safetensors").is_file()


def test_sac_checkpoint_restores_buffer_normalization_and_networks(tmp_path):
    from motorlab.rl.checkpoint import load_checkpoint
    from motorlab.rl.config import resolve
    from motorlab.rl.sb3 import build_model
    from motorlab.runs import read_config

    out = tmp_path / "sac"
    args = ["--algo", "sac", "--timesteps", "900", "--normalize", "--set", "learning_starts=100",
            "--set", "gradient_steps=1", "--set", 'policy_kwargs={"net_arch":[32,32]}', "--checkpoint-every", "200"]
    at = _train_and_kill(out, args, 400)
    folder = out / "checkpoint"
    record = json.loads((folder / "latest.json").read_text())
    model = build_model(resolve(read_config(out)), tmp_path / "scratch")
    load_checkpoint(out, model)
    assert model.num_timesteps == at
    with np.load(folder / record["files"]["buffer"]) as z:
        assert model.replay_buffer.pos == int(z["pos"]) > 0
        np.testing.assert_array_equal(model.replay_buffer.observations[: len(z["observations"])], z["observations"])
    with np.load(folder / record["files"]["normalize"]) as z:
        np.testing.assert_array_equal(model.get_env().obs_rms.mean, z["mean"])
    saved = load_file(folder / record["files"]["model"])
    for name, value in model.policy.state_dict().items():  # the networks, as saved
        np.testing.assert_array_equal(value.numpy(), saved[f"params/policy/{name}"], err_msg=name)
    assert model.actor.optimizer.state_dict()["state"]  # Adam's moments came back too
    model.get_env().close()
    assert_ok(run_cli("train", "--resume", out, "--no-progress"))
    assert read_summary(out)["timesteps"] == 900


def test_checkpoint_never_unpickles_objects(tmp_path):
    """A model file swapped for a pickle of an arbitrary object is refused, not executed:
    checkpoints are safetensors and JSON, never unpickled."""
    from motorlab.rl.checkpoint import load_checkpoint
    from motorlab.rl.config import resolve
    from motorlab.rl.sb3 import build_model

    folder = tmp_path / "run" / "checkpoint"
    folder.mkdir(parents=True)
    marker = tmp_path / "pwned"

    class Exploit:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    (folder / "model-1.safetensors").write_bytes(pickle.dumps(Exploit()))
    (folder / "model-1.json").write_text("{}")
    (folder / "latest.json").write_text(json.dumps({"steps": 1, "n_updates": 0, "episode_num": 0, "tracker": {},
                                                    "files": {"model": "model-1.safetensors",
                                                              "model_json": "model-1.json"}}))
    model = build_model(resolve({"env": {"id": ENV_ID}}), tmp_path / "scratch")
    with pytest.raises(MotorlabError, match="damaged"):
        load_checkpoint(tmp_path / "run", model)
    assert not marker.exists()
    model.get_env().close()


def test_metrics_writer_drops_rows_past_the_checkpoint_and_torn_lines(tmp_path):
    path = tmp_path / "metrics.csv"
    w = MetricsWriter(path, ["timesteps", "x"])
    for t in (10, 20, 30):
        w.write({"timesteps": t, "x": t / 10})
    w.close()
    with open(path, "a") as f:
        f.write("40,4")  # a kill mid-line: no newline
    w = MetricsWriter(path, ["timesteps", "x"], keep_until=20)
    w.write({"timesteps": 25, "x": 2.5})
    w.close()
    rows = list(csv.DictReader(path.read_text().splitlines()))
    assert [r["timesteps"] for r in rows] == ["10", "20", "25"]


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(old_extra=st.lists(st.sampled_from(["a", "b", "c"]), unique=True),
       new_extra=st.lists(st.sampled_from(["b", "c", "d"]), unique=True),
       steps=st.lists(st.integers(0, 100), min_size=1, max_size=8), cut=st.integers(0, 100))
def test_metrics_writer_keeps_every_row_when_resumed_under_other_columns(tmp_path_factory, old_extra, new_extra,
                                                                         steps, cut):
    """A run resumed by a motorlab whose metrics.csv has other columns (train_seconds came later) loses
    no row: each cell moves under its name, a new column stays empty, a dropped one goes."""
    path = tmp_path_factory.mktemp("m") / "metrics.csv"
    old, new = ["timesteps", *old_extra], ["timesteps", *new_extra]
    w = MetricsWriter(path, old)
    for t in steps:
        w.write({"timesteps": t, **{k: f"{k}{t}" for k in old_extra}})
    w.close()
    MetricsWriter(path, new, keep_until=cut).close()
    rows = list(csv.DictReader(path.read_text().splitlines()))
    assert [int(r["timesteps"]) for r in rows] == [t for t in steps if t <= cut]
    for r in rows:
        assert list(r) == new
        assert all(r[k] == (f"{k}{r['timesteps']}" if k in old_extra else "") for k in new_extra)


def test_resume_mistakes_are_one_clear_line(ppo_run, tmp_path):
    assert_one_line_error(run_here("train", "--resume", ppo_run), "finished already")
    assert_one_line_error(run_here("train", "--resume", tmp_path), "not a training run folder")
    assert_one_line_error(run_here("train", "--resume", ppo_run, "--timesteps", "5"), "drop the other settings")
