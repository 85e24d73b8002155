"""docs/hooks/benchmark_table.py, the MkDocs hook that writes docs/benchmarks.md's table of recorded
results: every fact it shows is its JSON's value, and a benchmark without a result file reads "not
yet run"."""

from __future__ import annotations

import importlib.util
import json
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.fast


def _hook():
    spec = importlib.util.spec_from_file_location("benchmark_table", ROOT / "docs/hooks/benchmark_table.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up
    spec.loader.exec_module(module)
    return module


table = _hook()
RESULTS = ROOT / "benchmarks" / "results"


def test_every_fact_in_the_table_is_its_jsons_value():
    rendered = table.render(RESULTS)
    files = sorted(RESULTS.glob("*.json"))
    assert files, "no recorded benchmark results"
    shown = 0
    for path in files:
        data = json.loads(path.read_text())
        row = next(line for line in rendered.splitlines() if f"`{path.name}`" in line)
        for fact in table.facts(data["benchmark"], data):
            value = fact.value(data)  # the path exists in the file
            assert fact.text(data) in row, (path.name, fact.label)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and fact.form == "ms":
                assert f"{value:.1f} ms" in row  # the number itself, as the file holds it
            shown += 1
        commit = (data.get("git") or {}).get("commit")
        if commit:
            assert f"`{commit[:7]}`" in row
    assert shown >= 20


def test_a_benchmark_without_a_result_file_reads_not_yet_run(tmp_path):
    empty = table.render(tmp_path)
    scripts = table.scripts()
    assert "mbrl" in scripts and "provenance" not in scripts  # a helper module is no benchmark
    for script in scripts:
        row = next(line for line in empty.splitlines() if f"`{script}.py`" in line)
        assert row.endswith("not yet run |"), row
    shutil.copy(RESULTS / "plan_latency.json", tmp_path / "plan_latency.json")
    one = table.render(tmp_path)
    assert "`plan_latency.json`" in one and "not yet run" not in next(
        line for line in one.splitlines() if "`plan_latency.py`" in line)


def test_a_benchmark_the_table_does_not_know_shows_whether_its_targets_are_met():
    facts = table.facts("a_new_benchmark", {"meets_target": False, "speedup": 2.0})
    assert [f.text({"meets_target": False}) for f in facts] == ["target met: **no**"]
    data = {"met": {"plain_median_steps": True, "delayed_median_steps": None}}
    assert [f.text(data) for f in table.facts("a_new_benchmark", data)] == [
        "plain_median_steps met: yes", "delayed_median_steps met: –"]  # None: the censoring left it open


def test_the_page_and_the_docs_build_use_the_hook():
    assert table.PLACEHOLDER in (ROOT / "docs" / "benchmarks.md").read_text()
    assert "docs/hooks/benchmark_table.py" in (ROOT / "mkdocs.yml").read_text()
