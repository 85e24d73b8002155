"""benchmarks/provenance.py: a recorded benchmark names the code that ran, read when it started."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import provenance  # noqa: E402
from provenance import Harness, SeedPlan, git_state, settings_hash  # noqa: E402


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


# ---- development vs headline: the harness ------------------------------------------------------

PLAN = SeedPlan(development=range(0, 100), headline=range(100, 1000))


@given(st.lists(st.integers(0, 1200), min_size=1, max_size=8))
@settings(max_examples=200, deadline=None)
def test_a_run_is_development_or_headline_never_both(seeds):
    dev = all(s < 100 for s in seeds)
    head = all(100 <= s < 1000 for s in seeds)
    if dev or head:
        assert PLAN.mode(seeds) == ("development" if dev else "headline")
    else:
        with pytest.raises(SystemExit, match="mix development seeds|in neither"):
            PLAN.mode(seeds)


def test_overlapping_seed_sets_are_refused():
    with pytest.raises(ValueError, match="overlap"):
        SeedPlan(development=range(0, 10), headline=range(5, 20))


def _clean(monkeypatch, commit="a" * 40, changed=()):
    state = {"commit": commit, "dirty": bool(changed), "changed_files": list(changed)}
    monkeypatch.setattr(provenance, "git_state",
                        lambda at_start=None: state if at_start is None else {**at_start, "changed_during_run": False})
    return state


def test_development_runs_write_only_the_devlog(tmp_path, monkeypatch, capsys):
    _clean(monkeypatch)
    harness = Harness("demo", PLAN, results=tmp_path / "results", devlog=tmp_path / "devlog")
    for lr in (1e-3, 3e-4, 1e-3):  # two distinct configurations, one tried twice
        run = harness.start([0, 1], {"lr": lr, "env": "Reacher-v5"})
        assert run.mode == "development"
        run.finish({"return": -5.0})
    assert not (tmp_path / "results").exists()  # never a result file from development seeds
    lines = provenance.devlog_entries("demo", tmp_path / "devlog")
    assert [e["settings"]["lr"] for e in lines] == [1e-3, 3e-4, 1e-3]
    assert lines[0]["settings_hash"] == settings_hash({"env": "Reacher-v5", "lr": 1e-3}) == lines[2]["settings_hash"]
    assert provenance.configurations_tried(lines) == 2 and lines[0]["seeds"] == [0, 1]


def test_a_headline_records_the_settings_hash_and_the_configurations_tried_before_it(tmp_path, monkeypatch, capsys):
    _clean(monkeypatch)
    harness = Harness("demo", PLAN, results=tmp_path / "results", devlog=tmp_path / "devlog")
    for lr in (1e-3, 3e-4, 1e-4):
        harness.start([0], {"lr": lr}).finish({"return": lr})
    run = harness.start([100, 101, 102], {"lr": 3e-4})
    assert run.mode == "headline"
    out = run.finish({"return": -4.0}, used={"seed 100": {"lr": 3e-4}})
    written = json.loads((tmp_path / "results" / "demo.json").read_text())
    assert written == out and written["return"] == -4.0
    prov = written["provenance"]
    assert prov["settings_hash"] == settings_hash({"lr": 3e-4}) and prov["seeds"] == [100, 101, 102]
    assert prov["development"]["configurations_tried"] == 3 and prov["development"]["runs"] == 3
    assert [e["result"] for e in prov["development"]["in_sample"]] == [{"return": 3e-4}]  # the in-sample number


def test_a_headline_refuses_settings_that_changed_during_the_run(tmp_path, monkeypatch, capsys):
    _clean(monkeypatch)
    harness = Harness("demo", PLAN, results=tmp_path / "results", devlog=tmp_path / "devlog")
    run = harness.start([100], {"horizon": 15})
    with pytest.raises(SystemExit, match="other settings"):
        run.finish({"return": 1.0}, used={"seed 100": {"horizon": 20}})  # a seed's process resolved another value
    assert not (tmp_path / "results").exists()


def test_a_headline_needs_committed_code_and_refuses_code_that_changed(tmp_path, monkeypatch, capsys):
    _clean(monkeypatch, changed=["motorlab/envs/catalog.py"])
    harness = Harness("demo", PLAN, results=tmp_path / "results", devlog=tmp_path / "devlog")
    with pytest.raises(SystemExit, match="catalog.py"):
        harness.start([100], {"x": 1})
    harness.start([0], {"x": 1})  # development runs may try uncommitted settings
    _clean(monkeypatch, changed=["benchmarks/results/mbrl-reacher.json", "benchmarks/devlog/x.jsonl"])
    run = harness.start([100], {"x": 1})  # its own outputs are no code
    monkeypatch.setattr(provenance, "git_state", lambda at_start=None: {**at_start, "changed_during_run": True})
    with pytest.raises(SystemExit, match="changed during the headline"):
        run.finish({"r": 1})
    assert not (tmp_path / "results").exists()


def test_a_headlines_in_sample_numbers_can_be_matched_on_one_part_of_its_settings(tmp_path, monkeypatch, capsys):
    _clean(monkeypatch)
    harness = Harness("demo", PLAN, results=tmp_path / "results", devlog=tmp_path / "devlog")
    harness.start([0], {"loop": {"h": 15}, "sac": "3 seeds"}).finish({"k": 5})  # the loop as the headline runs it
    harness.start([0], {"loop": {"h": 20}, "sac": "3 seeds"}).finish({"k": 2})
    out = harness.start([100], {"loop": {"h": 15}, "sac": "5 seeds, tuned"}, in_sample_key="loop").finish({"k": 3})
    dev = out["provenance"]["development"]
    assert [e["result"] for e in dev["in_sample"]] == [{"k": 5}] and dev["configurations_tried"] == 2
