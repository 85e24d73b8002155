"""Run folders: atomic writes, JSON-safe summaries, finished vs unfinished folders."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab.errors import MotorlabError
from motorlab.runs import (
    MetricsWriter,
    atomic_write_text,
    is_complete,
    prepare_run_dir,
    read_config,
    read_json,
    read_metrics,
    require_run_dir,
    run_folders,
    write_config,
    write_json,
    write_summary,
    write_toml,
)
from tests.helpers import snapshot

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def test_write_json_is_plain_json(tmp_path):
    path = tmp_path / "s.json"
    write_json(path, {"a": np.float32(1.5), "b": np.int64(3), "nan": math.nan, "inf": np.inf,
                      "arr": np.arange(3), "nested": {"x": (np.float64(2.0), None)}})
    text = path.read_text()
    data = json.loads(text)  # strict JSON: NaN/Infinity would not be valid
    assert "NaN" not in text and "Infinity" not in text
    assert data == {"a": 1.5, "b": 3, "nan": None, "inf": None, "arr": [0, 1, 2], "nested": {"x": [2.0, None]}}


def test_atomic_write_replaces_whole_file_and_leaves_no_temp(tmp_path):
    path = tmp_path / "deep" / "file.txt"
    atomic_write_text(path, "first")
    atomic_write_text(path, "second")
    assert path.read_text() == "second"
    assert [p.name for p in path.parent.iterdir()] == ["file.txt"]


def test_config_round_trip_drops_none(tmp_path):
    write_config(tmp_path, {"algo": "ppo", "lr": None, "env": {"id": "X", "delay": None, "history": 2}})
    assert read_config(tmp_path) == {"algo": "ppo", "env": {"id": "X", "history": 2}}


@pytest.mark.parametrize("content, fragment", [(None, "missing"), ('{"a": ', "JSON")])
def test_read_json_errors(tmp_path, content, fragment):
    path = tmp_path / "x.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(MotorlabError, match=fragment):
        read_json(path)


def test_read_config_errors(tmp_path):
    with pytest.raises(MotorlabError, match="config.toml"):
        read_config(tmp_path)
    (tmp_path / "config.toml").write_text("a = [")
    with pytest.raises(MotorlabError, match="TOML"):
        read_config(tmp_path)


def _run_folder(path, kind: str = "train"):
    """A folder a motorlab run of `kind` made (its marker), as these tests build runs by hand."""
    from motorlab import claims

    path.mkdir(parents=True)
    claims.mark(path, kind)
    return path


def test_prepare_run_dir_refuses_a_finished_run_and_resume_marks_it_unfinished(tmp_path):
    run = _run_folder(tmp_path / "run")
    write_summary(run, {"x": 1})
    (run / "artifact.bin").write_bytes(b"keep")
    before = snapshot(run)
    with pytest.raises(MotorlabError, match="finished run.*--overwrite"):
        prepare_run_dir(run, "train")
    assert snapshot(run) == before  # refused before anything was touched
    with run_folders("resume"):
        assert prepare_run_dir(run, "train") == run
    assert not is_complete(run)  # a stale summary would make a half-written run look finished
    assert (run / "artifact.bin").read_bytes() == b"keep"


def test_a_damaged_summary_is_no_finished_run(tmp_path):
    run = _run_folder(tmp_path / "run")
    (run / "summary.json").write_text('{"x": 1')  # cut short
    assert not is_complete(run)
    (run / "summary.json").write_text("[1, 2]")  # JSON, but not a summary
    assert not is_complete(run)
    assert prepare_run_dir(run, "train") == run  # an unfinished run may be written into


def test_overwrite_replaces_the_folder_whole_once_the_new_run_finished(tmp_path):
    run = _run_folder(tmp_path / "run")
    (run / "tensorboard").mkdir(parents=True)
    (run / "tensorboard" / "events.old").write_bytes(b"old curves")
    write_summary(run, {"x": 1})
    with run_folders("overwrite"):
        prepare_run_dir(run, "train")
        assert not (run / "tensorboard").exists()  # old events never mix with the new run's
        write_summary(run, {"x": 2})
    assert read_json(run / "summary.json") == {"x": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # the old run is gone, nothing left aside


@pytest.mark.parametrize("failure", [RuntimeError, KeyboardInterrupt])
def test_overwrite_puts_the_old_run_back_when_the_new_one_fails(tmp_path, failure):
    run = _run_folder(tmp_path / "run")
    (run / "policy.json").write_text("{}")
    write_summary(run, {"x": 1})
    before = snapshot(tmp_path)
    with pytest.raises(failure), run_folders("overwrite"):
        prepare_run_dir(run, "train")
        (run / "policy.json").write_text('{"half": "written"}')
        raise failure()
    assert snapshot(tmp_path) == before


def test_a_killed_overwrite_is_settled_by_the_next_command(tmp_path):
    # what a SIGKILL leaves: the old run aside (its process gone), the new one unfinished
    run = tmp_path / "run"
    aside = _run_folder(tmp_path / ".run.replaced-20260101-000000-999999999")
    write_summary(aside, {"x": 1})
    _run_folder(run)
    (run / "metrics.csv").write_text("half")
    with pytest.raises(MotorlabError, match="finished run"):
        prepare_run_dir(run, "train")  # the old run is back, and finished: refused as ever
    assert read_json(run / "summary.json") == {"x": 1} and not aside.exists()


def test_prepare_run_dir_rejects_a_file(tmp_path):
    path = tmp_path / "file"
    path.write_text("x")
    with pytest.raises(MotorlabError, match="file"):
        prepare_run_dir(path, "train")


def test_require_run_dir(tmp_path, monkeypatch):
    with pytest.raises(MotorlabError, match="does not exist"):
        require_run_dir(tmp_path / "missing")
    (tmp_path / "a-file").write_text("x")
    with pytest.raises(MotorlabError, match="not a folder"):
        require_run_dir(tmp_path / "a-file")
    run = tmp_path / "run"
    run.mkdir()
    with pytest.raises(MotorlabError, match="summary.json"):
        require_run_dir(run)
    write_summary(run, {})
    assert require_run_dir(run) == run
    # Permissions cannot be taken from root (the tests may run as root): simulate them.
    import motorlab.runs

    monkeypatch.setattr(motorlab.runs.os, "access", lambda path, mode: False)
    with pytest.raises(MotorlabError, match="not readable"):
        require_run_dir(run)


def test_metrics_round_trip(tmp_path):
    writer = MetricsWriter(tmp_path / "metrics.csv", ["timesteps", "episode_return", "eval_return_mean"])
    writer.write({"timesteps": 10, "episode_return": np.float32(9.0)})
    writer.write({"timesteps": 20, "eval_return_mean": 12.5, "ignored": 1})
    # Each row is flushed as it is written: readable before close (an interrupted run keeps its rows).
    rows = read_metrics(tmp_path)
    writer.close()
    assert len(rows) == 2
    assert rows[0]["timesteps"] == 10 and rows[0]["episode_return"] == 9.0 and math.isnan(rows[0]["eval_return_mean"])
    assert rows[1]["eval_return_mean"] == 12.5 and math.isnan(rows[1]["episode_return"])
    assert "ignored" not in rows[1]


def test_read_metrics_missing(tmp_path):
    with pytest.raises(MotorlabError, match="metrics.csv"):
        read_metrics(tmp_path)



def test_atomic_writes_get_normal_file_permissions(tmp_path):
    """Plots, videos and summaries are as readable as any file the user writes (not mkstemp's 0600)."""
    from motorlab.claims import current_umask
    from motorlab.runs import atomic_write_text

    atomic_write_text(tmp_path / "a.txt", "x")
    with open(tmp_path / "b.txt", "w") as f:  # what plain open() gives under this umask
        f.write("y")
    mode = (tmp_path / "a.txt").stat().st_mode & 0o777
    assert mode == (tmp_path / "b.txt").stat().st_mode & 0o777 == 0o666 & ~current_umask()


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(password=st.text(st.characters(codec="ascii", exclude_characters="/@?#[]\\ \t\n\r\x0b\x0c\"'"), min_size=4,
                        max_size=16).filter(lambda p: p.strip() and "***" not in p),
       where=st.sampled_from(["setting", "key", "list", "nested"]))
def test_no_credential_reaches_a_run_folders_json_or_toml(tmp_path_factory, password, where):
    """Whatever a run records (settings, targets, commands, summaries) passes one masking function."""
    from urllib.parse import quote

    url = f"http://user:{quote(password, safe='')}@host:5000"
    text = f"train X --track mlflow={url} --seed 1"
    data = {"setting": {"target": text}, "key": {text: 1}, "list": {"commands": [text, "plain"]},
            "nested": {"a": {"b": [{"c": text}]}}}[where]
    folder = tmp_path_factory.mktemp("masked")
    write_json(folder / "summary.json", data)
    write_toml(folder / "config.toml", data)
    for name in ("summary.json", "config.toml"):
        written = (folder / name).read_text()
        assert quote(password, safe="") not in written and "user:***@host:5000" in written.replace("\\", "")
