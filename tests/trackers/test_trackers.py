"""Experiment tracking (`--track mlflow[=URI]`, `--track wandb`): each run mirrored, live, to MLflow or
W&B, read back with their own clients and formats; sweeps group their trials under a parent run;
a missing package, an unreachable server or an unwritable store is one line before anything is
written, and a tracker failing during a run warns once and never fails the run.

The MLflow tests share one SQLite store (creating its tables takes seconds); each finds its runs
by the run folder they tagged.
"""

from __future__ import annotations

import contextvars
import json
import os
import struct
import sys
import threading
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from motorlab import trackers
from motorlab.errors import MotorlabError
from motorlab.trackers import mlflow as mlflow_tracker
from motorlab.trackers import tracked as tracked_runs
from tests.helpers import ENV_ID, TINY_PPO, assert_ok, assert_one_line_error, read_summary, run_cli

NEVER = ("model.zip", "policy.safetensors", "policy.json", "checkpoint", "tensorboard")


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> str:
    """One MLflow SQLite store for the file's runs."""
    return f"sqlite:///{tmp_path_factory.mktemp('mlflow') / 'mlflow.db'}"


def client(store: str):
    from mlflow.tracking import MlflowClient

    return MlflowClient(store)


def runs_of(store: str, folder: Path) -> list:
    """The MLflow runs of the run folders under `folder` (tagged motorlab.run_dir)."""
    c = client(store)
    found = c.search_runs([e.experiment_id for e in c.search_experiments()], max_results=1000)
    return [r for r in found if Path(r.data.tags.get("motorlab.run_dir", "/")).is_relative_to(folder.resolve())]


def tensorboard_scalars(run_dir: Path) -> Counter:
    """Every scalar TensorBoard got, as (tag, step, float32 value), from the event files themselves."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    points: Counter = Counter()
    for folder in (run_dir / "tensorboard").iterdir():
        events = EventAccumulator(str(folder), size_guidance={"scalars": 0})
        events.Reload()
        for tag in events.Tags()["scalars"]:
            points.update((tag, e.step, np.float32(e.value)) for e in events.Scalars(tag))
    return points


@pytest.mark.fast
def test_track_values_and_files_a_run_shares(tmp_path):
    """--track values parse (one tracker once each), and a run folder's files the trackers get leave the models out."""
    assert trackers.parse(["mlflow", "wandb=my-project"]) == [trackers.Target("mlflow"),
                                                               trackers.Target("wandb", "my-project")]
    assert trackers.parse("mlflow=sqlite:///x.db") == [trackers.Target("mlflow", "sqlite:///x.db")]
    for bad in (["neptune"], ["mlflow="], ["mlflow", "mlflow=file:///x"]):
        with pytest.raises(MotorlabError):
            trackers.parse(bad)
    for name in ("config.toml", "summary.json", "results.json", "metrics.csv", "model.zip", "policy.json",
                 "policy.safetensors", "transitions.npz", "plots/learning_curve.png", "videos/episode_0.mp4",
                 "tensorboard/PPO_1/events.out.tfevents.1", "checkpoint/state.json"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("x")
    shared = {(Path(folder) / p.name).as_posix() for p, folder in trackers.run_files(tmp_path)}
    assert shared == {"config.toml", "summary.json", "results.json", "metrics.csv", "plots/learning_curve.png",
                      "videos/episode_0.mp4"}
    # the resolved default store is absolute, so child processes anywhere use the same one
    resolved = mlflow_tracker.resolve(trackers.Target("mlflow", "sqlite:///rel/mlflow.db"))
    assert resolved.where == f"sqlite:///{Path.cwd() / 'rel' / 'mlflow.db'}"



def test_train_mirrors_tensorboard_config_summary_and_plots_to_mlflow(store, tmp_path):
    run_dir = tmp_path / "ppo"
    proc = run_cli("train", ENV_ID, *TINY_PPO, "--no-progress", "--track", f"mlflow={store}", "--out", run_dir)
    assert_ok(proc)
    assert "tracked: MLflow run" in proc.stderr and "warning" not in proc.stderr
    (run,) = runs_of(store, run_dir)
    c = client(store)
    assert run.info.status == "FINISHED" and run.data.tags["motorlab.kind"] == "train"
    assert run.data.tags["motorlab.seed"] == "0"
    # the scalars are TensorBoard's: the same tags, steps and values, SB3's and motorlab's own
    tb = tensorboard_scalars(run_dir)
    tags = {t for t, _, _ in tb}
    assert {"rollout/ep_rew_mean", "train/value_loss", "eval/return_mean", "train/episode_return"} <= tags
    tracked = Counter((tag, m.step, np.float32(m.value)) for tag in tags
                      for m in c.get_metric_history(run.info.run_id, tag))
    assert tracked == tb
    assert {k for k in run.data.metrics if "/" in k} == tags  # and no scalar TensorBoard did not get
    assert {s for t, s, _ in tb if t == "eval/return_mean"} == {128, 256}  # evaluated after each rollout
    # the resolved settings as params, the summary's numbers as metrics
    params = run.data.params
    assert params["env.id"] == ENV_ID and params["algo"] == "ppo" and params["hyperparams.n_steps"] == "128"
    summary = read_summary(run_dir)
    assert run.data.metrics["eval_return_mean"] == pytest.approx(summary["eval_return_mean"])
    # the files people read, not the model
    top = {f.path for f in c.list_artifacts(run.info.run_id)}
    assert {"summary.json", "config.toml", "results.json", "metrics.csv", "plots"} <= top
    assert [f.path for f in c.list_artifacts(run.info.run_id, "plots")] == ["plots/learning_curve.png"]
    assert not any(name in path for path in top for name in NEVER)
    local = Path(c.download_artifacts(run.info.run_id, "summary.json", str(tmp_path / "download")))
    assert json.loads(local.read_text()) == summary


def wandb_records(run_folder: Path) -> list:
    """The records of an offline W&B run's .wandb file: W&B's LevelDB-style log (32 KiB blocks, each
    record's chunks behind a 7-byte header: CRC, length, type) of wandb_internal_pb2.Record messages."""
    from wandb.proto import wandb_internal_pb2

    (path,) = run_folder.glob("*.wandb")
    data = path.read_bytes()
    assert data[:4] == b":W&B"
    records, pos, chunks = [], 7, b""
    while pos + 7 <= len(data):
        if 32768 - pos % 32768 < 7:  # a block's tail too short for a header is padding
            pos += 32768 - pos % 32768
            continue
        _crc, length, kind = struct.unpack("<IHB", data[pos:pos + 7])
        chunk, pos = data[pos + 7:pos + 7 + length], pos + 7 + length
        if kind == 0:
            continue
        chunks = chunk if kind in (1, 2) else chunks + chunk  # full or first; middle or last
        if kind in (1, 4):
            record = wandb_internal_pb2.Record()
            record.ParseFromString(chunks)
            records.append(record)
    return records


def test_wandb_offline_run_holds_config_scalars_summary_and_files(tmp_path, monkeypatch):
    """No API key, no network: the run is an offline W&B folder, syncable later."""
    for name in ("WANDB_API_KEY", "WANDB_MODE", "WANDB_DIR", "WANDB_PROJECT", "NETRC"):
        monkeypatch.delenv(name, raising=False)
    env = {"HOME": str(tmp_path)}  # no ~/.netrc: no API key
    run_dir = tmp_path / "ppo"
    proc = run_cli("train", ENV_ID, *TINY_PPO, "--no-progress", "--track", "wandb", "--out", run_dir, cwd=tmp_path,
                   env=env)
    assert_ok(proc)
    (folder,) = (tmp_path / "wandb").glob("offline-run-*")
    assert f"wandb sync {folder}" in proc.stderr
    records = wandb_records(folder)
    (run,) = [r.run for r in records if r.WhichOneof("record_type") == "run"]
    config = {item.key: json.loads(item.value_json) for item in run.config.update}
    assert run.project == "motorlab" and run.job_type == "train" and run.display_name == "ppo"
    assert config["env"]["id"] == ENV_ID and config["hyperparams"]["n_steps"] == 128
    history: Counter = Counter()
    for r in records:
        if r.WhichOneof("record_type") == "history":
            row = {"/".join(item.nested_key) or item.key: json.loads(item.value_json) for item in r.history.item}
            history.update((k, row["global_step"], np.float32(v)) for k, v in row.items()
                           if not k.startswith("_") and k != "global_step")
    assert history == tensorboard_scalars(run_dir)  # TensorBoard's tags, steps (global_step) and values
    summary = {}
    for r in records:
        if r.WhichOneof("record_type") == "summary":
            summary.update({"/".join(i.nested_key) or i.key: json.loads(i.value_json) for i in r.summary.update})
    assert summary["eval_return_mean"] == pytest.approx(read_summary(run_dir)["eval_return_mean"])
    files = folder / "files"
    assert json.loads((files / "summary.json").read_text()) == read_summary(run_dir)
    assert (files / "plots" / "learning_curve.png").read_bytes() == (run_dir / "plots/learning_curve.png").read_bytes()
    assert not any((files / name).exists() for name in NEVER)


def test_sweep_trials_nest_under_the_sweeps_run(store, tmp_path):
    out = tmp_path / "sweep"
    # LQR trials (a second each): what is checked is the nesting; SB3's scalars are the test above's
    target = f"train {ENV_ID} --preset fast --until-solved --timesteps 1500 --solve-episodes 2"
    proc = run_cli("sweep", target, "--seeds", "2", "--max-parallel", "2", "--track", f"mlflow={store}", "--out", out)
    assert_ok(proc)
    runs = runs_of(store, out)
    (parent,) = [r for r in runs if r.data.tags["motorlab.kind"] == "sweep"]
    children = [r for r in runs if r is not parent]
    assert parent.info.status == "FINISHED" and parent.info.run_name == "sweep"
    assert sorted(r.info.run_name for r in children) == ["default/seed0", "default/seed1"]
    assert sorted(r.data.tags["motorlab.seed"] for r in children) == ["0", "1"]
    for r in children:  # one run per trial, each in its own process, nested under the sweep's
        assert r.data.tags["mlflow.parentRunId"] == parent.info.run_id and r.info.status == "FINISHED"
        assert r.info.experiment_id == parent.info.experiment_id
        assert "eval/return_mean" in r.data.metrics
    top = {f.path for f in client(store).list_artifacts(parent.info.run_id)}
    assert {"summary.json", "table.txt", "report.html", "aggregate.json", "config.toml"} <= top
    assert parent.data.params["sweep"] == target


def test_missing_package_is_one_line_with_the_pip_command(tmp_path):
    out = tmp_path / "run"
    blocked = ("import sys; sys.modules['mlflow'] = None; sys.argv = ['motorlab', *sys.argv[1:]]; "
               "from motorlab.cli import main; main()")
    import subprocess

    proc = subprocess.run([sys.executable, "-c", blocked, "train", ENV_ID, *TINY_PPO, "--track", "mlflow", "--out",
                           str(out)], capture_output=True, text=True, timeout=120)
    assert_one_line_error(proc, "--track mlflow needs MLflow", "pip install 'motorlab[mlflow]'",
                          "mlflow-skinny==3.17.2")
    assert not out.exists()


def test_unreachable_server_or_unknown_tracker_is_one_line_before_anything_is_written(tmp_path):
    out = tmp_path / "run"
    proc = run_cli("train", ENV_ID, *TINY_PPO, "--track", "mlflow=http://127.0.0.1:1", "--out", out, timeout=60)
    assert_one_line_error(proc, "mlflow=http://127.0.0.1:1", "no MLflow tracking server answers")
    proc = run_cli("mpc", "Reacher-v5", "--model", tmp_path, "--track", "neptune", "--out", out, timeout=60)
    assert_one_line_error(proc, "--track 'neptune'", "mlflow=URI")
    assert not out.exists()


@pytest.fixture
def fresh_failures(monkeypatch):
    """The failures and warnings the trackers remember in this process are this test's own."""
    monkeypatch.setattr(tracked_runs, "_broken", set())
    monkeypatch.setattr(tracked_runs, "_warned", set())


def tracked_as_a_child(value: str):
    """Track the runs of the block as a child process would (a handoff adopted: no up-front check)."""
    return trackers.adopted({"track": [value]})


def train_here(run_dir: Path):
    from motorlab.kinds.train import TRAIN

    settings = TRAIN.make(env={"id": ENV_ID}, algo="ppo", timesteps=256, hyperparams={"n_steps": 128, "batch_size": 64})
    return TRAIN.run(settings, run_dir, progress=False)


def test_unwritable_store_at_run_time_warns_once_and_the_run_completes(fresh_failures, tmp_path, capsys):
    """The store cannot be made (nothing checked it first): MLflow fails as the run starts; one warning
    line, and the run finishes as it would untracked."""
    run_dir = tmp_path / "ppo"
    with tracked_as_a_child("mlflow=sqlite:////proc/no-such-folder/mlflow.db"):
        assert train_here(run_dir).timesteps == 256
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("warning: tracking to MLflow failed"), lines
    assert read_summary(run_dir)["timesteps"] == 256 and (run_dir / "plots/learning_curve.png").is_file()


def test_python_api_tracks_and_a_failure_mid_run_warns_once(store, fresh_failures, tmp_path, monkeypatch, capsys):
    """kind.run from Python, tracked inside a tracking block; the store fails on the first scalars it
    gets (a mocked log_batch): one warning, the run finishes and its folder is complete."""
    calls = []

    def fail(self, rows):
        calls.append(len(rows))
        raise OSError("attempt to write a readonly database")

    monkeypatch.setattr(mlflow_tracker.Sink, "scalars", fail)
    run_dir = tmp_path / "api"
    with trackers.tracking(f"mlflow={store}"):
        assert train_here(run_dir).timesteps == 256 and read_summary(run_dir)["timesteps"] == 256
    assert len(calls) == 1 and calls[0] > 0  # tried once, then that tracker is off
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning")]
    assert len(warnings) == 1, warnings
    assert "tracking to MLflow failed (OSError: attempt to write a readonly" in warnings[0]
    (run,) = runs_of(store, run_dir)  # it started before the failure, with the resolved settings
    assert run.data.params["env.id"] == ENV_ID and run.data.tags["motorlab.kind"] == "train"


# ---- tracking is explicit: a block, never process state ---------------------------------------------

LQR = {"preset": "fast", "until_solved": True, "timesteps": 1500, "solve_episodes": 2, "progress": False}


def evaluate_zero(out: Path):
    """The cheapest step there is (a zero policy, one episode, milliseconds): a tracked run of kind evaluate."""
    import motorlab

    return motorlab.evaluate("zero", ENV_ID, episodes=1, workers=1, progress=False, out=out)


def test_track_given_to_one_call_tracks_that_call_only(store, tmp_path):
    """In a notebook, train(track=...) and then a plain train(...): one run in the store, not two."""
    import motorlab

    motorlab.train(ENV_ID, out=tmp_path / "tracked", track=f"mlflow={store}", **LQR)
    motorlab.train(ENV_ID, out=tmp_path / "plain", **LQR)
    (run,) = runs_of(store, tmp_path)
    assert Path(run.data.tags["motorlab.run_dir"]) == (tmp_path / "tracked").resolve()
    assert run.info.status == "FINISHED" and trackers.targets() == [] and trackers.handoff() is None


def test_a_tracking_block_tracks_every_call_inside_it_and_none_after(store, tmp_path):
    import motorlab

    with motorlab.tracking(f"mlflow={store}") as found:
        assert [t.backend for t in found] == ["mlflow"] and trackers.targets() == found
        evaluate_zero(tmp_path / "first")
        evaluate_zero(tmp_path / "second")
    evaluate_zero(tmp_path / "after")
    runs = runs_of(store, tmp_path)
    assert sorted(r.info.run_name for r in runs) == ["first", "second"]
    assert all(r.data.tags["motorlab.kind"] == "evaluate" and r.info.status == "FINISHED" for r in runs)
    assert trackers.targets() == []


@pytest.mark.fast
def test_tracking_checks_before_the_block_and_none_changes_nothing(tmp_path):
    """A tracker that cannot work is one error line before the block runs; tracking(None) or [] inside
    a block keeps the outer block's trackers, and each block restores what was before it."""
    with pytest.raises(MotorlabError, match="no MLflow tracking server answers"):
        with trackers.tracking("mlflow=http://127.0.0.1:1"):
            pytest.fail("the block ran")
    (tmp_path / "a-file").write_text("")
    with pytest.raises(MotorlabError, match="cannot write the MLflow store"):
        with trackers.tracking(f"mlflow=sqlite:///{tmp_path / 'a-file' / 'mlflow.db'}"):
            pytest.fail("the block ran")
    outer = f"mlflow=sqlite:///{tmp_path / 'mlflow.db'}"
    with trackers.tracking(outer) as found:
        for nothing in (None, [], ""):
            with trackers.tracking(nothing) as inner:
                assert inner == found == trackers.targets()
        with trackers.tracking([f"mlflow=sqlite:///{tmp_path / 'other.db'}"]) as inner:  # a list, as --track gives them
            assert trackers.targets() == inner != found
        assert trackers.targets() == found
    assert trackers.targets() == [] and trackers.handoff() is None
    assert not any(k.startswith("MOTORLAB_TRACK") for k in os.environ)  # nothing in the environment


@pytest.mark.fast
def test_steps_in_two_threads_are_each_their_own_tracked_run(monkeypatch, tmp_path):
    """A study runs train steps in threads, each in a copy of the context: each is a tracked step
    (with one step per process, the second would have been taken for part of the first)."""
    monkeypatch.setattr(tracked_runs, "_load", lambda found: found)  # no run is started: nothing to load
    both = threading.Barrier(2, timeout=30)
    seen = {}

    def one(kind: str) -> None:
        with trackers.step(kind, {"seed": 0}) as tracked:
            both.wait()  # both steps are open now
            seen[kind] = bool(tracked) and tracked_runs._current.get() is tracked and tracked.kind == kind
            both.wait()
        seen[kind] &= tracked_runs._current.get() is None

    with tracked_as_a_child(f"mlflow=sqlite:///{tmp_path / 'mlflow.db'}"):
        threads = [threading.Thread(target=contextvars.copy_context().run, args=(one, k)) for k in ("a", "b")]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
    assert seen == {"a": True, "b": True}


def test_a_child_that_adopts_the_handoff_nests_under_the_parent(store, fresh_failures, tmp_path):
    """handoff() is JSON for a child's job settings; a process that adopts it (here: an empty context,
    as a fresh process has) tracks its runs nested under the open parent, without checking again."""
    sweep_dir = tmp_path / "sweep"
    sweep_dir.mkdir()
    assert trackers.handoff() is None
    with trackers.tracking(f"mlflow={store}"), trackers.parent("sweep", sweep_dir, {"sweep": "zero"}):
        job = json.loads(json.dumps(trackers.handoff()))
        assert job["track"] == [f"mlflow={store}"] and job["parent"]["root"] == str(sweep_dir.resolve())

        def child() -> None:
            assert trackers.targets() == [] and trackers.handoff() is None  # nothing inherited
            with trackers.adopted(job):
                evaluate_zero(sweep_dir / "trials" / "0")
            with trackers.adopted(None):  # a job without tracking: none
                evaluate_zero(sweep_dir / "untracked")

        contextvars.Context().run(child)
    runs = runs_of(store, sweep_dir)
    (parent,) = [r for r in runs if r.data.tags["motorlab.kind"] == "sweep"]
    (trial,) = [r for r in runs if r is not parent]
    assert trial.info.run_name == "trials/0" and trial.data.tags["motorlab.parent"] == "sweep"
    assert trial.data.tags["mlflow.parentRunId"] == parent.info.run_id and trial.info.status == "FINISHED"
    assert trial.info.experiment_id == parent.info.experiment_id and parent.info.status == "FINISHED"


# ---- a sweep's or tune's target names its own --track: applied to its trials (issue 52) -------------------


def test_a_sweep_targets_own_track_tracks_its_trials(store, tmp_path):
    out = tmp_path / "sweep"
    target = f"train {ENV_ID} --algo lqr --timesteps 300 --solve-episodes 1 --track mlflow={store}"
    assert_ok(run_cli("sweep", target, "--seeds", "1", "--out", out))  # no --track of the sweep's own
    runs = runs_of(store, out)
    (parent,) = [r for r in runs if r.data.tags["motorlab.kind"] == "sweep"]
    (child,) = [r for r in runs if r is not parent]
    assert child.info.run_name == "default/seed0" and child.data.tags["mlflow.parentRunId"] == parent.info.run_id
    assert child.info.status == "FINISHED" and "eval/return_mean" in child.data.metrics


def test_a_tune_targets_own_track_tracks_its_trials(store, tmp_path):
    out = tmp_path / "tune"
    target = f"train {ENV_ID} --algo lqr --timesteps 300 --solve-episodes 1 --track mlflow={store}"
    assert_ok(run_cli("tune", target, "--space", "delay=uniform:0.05,0.2", "--trials", "1", "--seeds", "1",
                      "--fresh-seeds", "0", "--sampler", "random", "--pruner", "none", "--out", out))
    runs = runs_of(store, out)
    (parent,) = [r for r in runs if r.data.tags["motorlab.kind"] == "tune"]
    (child,) = [r for r in runs if r is not parent]
    assert child.info.run_name == "trials/0/seed0" and child.data.tags["mlflow.parentRunId"] == parent.info.run_id


@pytest.mark.fast
def test_a_targets_track_joins_the_outer_trackers_or_is_refused_when_they_disagree(tmp_path):
    one, other = f"mlflow=sqlite:///{tmp_path / 'one.db'}", f"mlflow=sqlite:///{tmp_path / 'other.db'}"
    with trackers.also([one]) as found:  # alone: it is the tracking
        assert [t.text() for t in found] == [one]
    assert trackers.targets() == []
    with trackers.tracking(one) as outer:
        with trackers.also([one]) as found:  # the same store, named twice: one tracker
            assert found == outer
        with trackers.also(["wandb"]) as found:  # another tracker: both
            assert [t.backend for t in found] == ["mlflow", "wandb"]
        with pytest.raises(MotorlabError, match="track one run to two places") as e:
            with trackers.also([other], "the sweep's target"):
                pytest.fail("the block ran")
        assert "\n" not in str(e.value) and "the sweep's target" in str(e.value)
        assert trackers.targets() == outer


@pytest.mark.fast
def test_what_a_tracker_records_holds_no_credential():
    """Params, tags and names of a tracked run pass through mask_secrets: a sweep's target quoting a password."""
    target = "train X --track mlflow=http://me:s3cretpw@host:5000"
    info = tracked_runs._info("sweep", None, {"sweep": target, "grid": [f"note={target}"], target: 1})
    assert "s3cretpw" not in json.dumps([info.name, info.config, info.tags])
    assert info.config["sweep"] == "train X --track mlflow=http://me:***@host:5000"
