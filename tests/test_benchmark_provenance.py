"""benchmarks/provenance.py: a recorded benchmark names the code that ran, read when it started."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from provenance import git_state  # noqa: E402


def test_git_state_keeps_the_start_and_flags_a_tree_that_changed_during_the_run():
    now = git_state()
    assert now["commit"] and len(now["commit"]) == 40 and isinstance(now["changed_files"], list)
    same = git_state(at_start=now)
    assert same == {**now, "changed_during_run": False}
    earlier = {**now, "commit": "0" * 40}  # a commit made while the run ran
    moved = git_state(at_start=earlier)
    assert moved["commit"] == "0" * 40 and moved["changed_during_run"] is True and moved["at_end"] == now


def test_a_recorded_run_writes_its_result_whole_with_where_it_came_from(tmp_path, capsys):
    import json

    from provenance import Recorder

    recorder = Recorder("demo", results=tmp_path)
    out = recorder.record({"per_seed": [1.0, 2.0], "targets": {"x": {"met": True}}})
    written = json.loads((tmp_path / "demo.json").read_text())
    assert written == out and json.loads(capsys.readouterr().out) == out  # printed, and the file is the same
    assert written["benchmark"] == "demo" and written["per_seed"] == [1.0, 2.0]
    assert written["git"]["commit"] == recorder.git["commit"] and "changed_during_run" in written["git"]
    assert written["date"][:2] == "20" and written["machine"]["cores"] >= 1 and written["versions"]["numpy"]
    assert isinstance(written["argv"], list)
    recorder.record({"per_seed": [3.0]}, file="demo-quick")  # a smoke run goes to its own file
    assert json.loads((tmp_path / "demo.json").read_text())["per_seed"] == [1.0, 2.0]
    assert not list(tmp_path.glob("*.tmp"))  # written through a temp file, renamed


def test_a_scripts_own_machine_facts_are_kept_beside_the_recorded_ones(tmp_path, capsys):
    from provenance import Recorder

    recorder = Recorder("demo", results=tmp_path)
    speed = recorder.record({"machine": {"legs_env_steps_per_second": 1022}})["machine"]
    assert speed["legs_env_steps_per_second"] == 1022 and speed["cores"] >= 1  # both, neither replaced
    assert recorder.record({"machine": "x86_64"})["machine"]["reported"] == "x86_64"
