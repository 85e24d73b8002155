"""The study runner and recipes know no step kind by name: a kind the test registers itself
runs through recipes, references, resuming and the study table like the bundled ones."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest
from pydantic import Field
from rich.console import Console

from motorlab import kinds
from motorlab.errors import MotorlabError
from motorlab.recipes import parse_recipe
from motorlab.report.results import Metric
from motorlab.runs import read_json, run_folders
from motorlab.settings import Settings, Summary
from motorlab.stepkind import Artifact, Ref, StepKind
from motorlab.studies import run_study

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

RUNS: list[str] = []  # the run folders the fake kind ran, in order


class DoubleSettings(Settings):
    value: float = Field(1.0, description="The number to double")
    source: str | None = Field(None, description="number.json of an earlier step, doubled instead of value")
    seed: int = Field(0, ge=0, description="Random seed (unused)")


class DoubleSummary(Summary):
    result: float
    source_value: float | None


class DoubleKind(StepKind[DoubleSettings, DoubleSummary]):
    """Doubles a number, or the number an earlier step wrote."""

    name = "double-for-test"
    settings = DoubleSettings
    summary = DoubleSummary
    refs = (Ref("source", ("number",)),)
    provides = Artifact("number", "number.json")

    def run(self, settings: DoubleSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DoubleSummary:
        source = read_json(Path(settings.source))["number"] if settings.source else None
        run_dir = self.start(out)
        RUNS.append(run_dir.name)
        result = 2 * (source if source is not None else settings.value)
        (run_dir / "number.json").write_text(json.dumps({"number": result}))
        return self.finish(run_dir, settings, DoubleSummary(result=result, source_value=source))

    def describe(self, settings: DoubleSettings, copies: int = 1) -> str:
        return f"double {settings.source or settings.value}"

    def headline(self, s: DoubleSummary) -> dict[str, Any]:
        return {"result": s.result}

    metrics = (Metric("result", "result"),)


@pytest.fixture
def registered(monkeypatch):
    monkeypatch.setitem(kinds.KINDS, DoubleKind.name, DoubleKind())
    RUNS.clear()


RECIPE = """
name = "doubling"
[[steps]]
name = "a"
kind = "double-for-test"
value = {value}
[[steps]]
name = "b"
kind = "double-for-test"
source = "@a"
"""


def quiet() -> Console:
    return Console(file=open(os.devnull, "w"))


def test_a_registered_kind_runs_in_a_study(registered, tmp_path):
    recipe = parse_recipe(RECIPE.format(value=3), "doubling.toml")
    assert [s.inputs() for s in recipe.steps] == [[], ["a"]]
    summary = run_study(recipe, tmp_path / "study", console=quiet())
    assert summary["a.result"] == 6 and summary["b.result"] == 12  # b read the number.json a wrote
    assert read_json(tmp_path / "study" / "b" / "summary.json") == {"result": 12.0, "source_value": 6.0}
    table = (tmp_path / "study" / "table.txt").read_text()
    assert "double 3.0" in table and "result 12" in table
    assert RUNS == ["a", "b"]


def test_finished_steps_are_kept_and_changed_inputs_redone(registered, tmp_path):
    run_study(parse_recipe(RECIPE.format(value=3), "doubling.toml"), tmp_path / "study", console=quiet())
    with pytest.raises(MotorlabError, match="finished run.*--resume"):  # a finished study is not redone by accident
        run_study(parse_recipe(RECIPE.format(value=3), "doubling.toml"), tmp_path / "study", console=quiet())
    with run_folders("resume"):
        run_study(parse_recipe(RECIPE.format(value=3), "doubling.toml"), tmp_path / "study", console=quiet())
    assert RUNS == ["a", "b"]  # the second run kept both
    with run_folders("resume"):
        summary = run_study(parse_recipe(RECIPE.format(value=5), "doubling.toml"), tmp_path / "study",
                            console=quiet())
    assert RUNS == ["a", "b", "a", "b"]  # a changed, so b (which reads it) ran again
    assert summary["b.result"] == 20
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]  # the replaced runs are gone


def test_a_reference_to_a_kind_that_provides_something_else_is_refused(registered):
    text = RECIPE.format(value=1) + """
[[steps]]
name = "c"
kind = "double-for-test"
source = "@d"
"""
    with pytest.raises(MotorlabError, match=r"source '@d' names no earlier double-for-test step; "
                                            r"double-for-test steps so far: a, b"):
        parse_recipe(text, "doubling.toml")


def test_unregistered_kinds_are_unknown():
    with pytest.raises(MotorlabError, match="unknown kind 'double-for-test'"):
        parse_recipe(RECIPE.format(value=1), "doubling.toml")


def test_kinds_that_fit_synergies_import_sklearn_before_a_study_starts_threads():
    # Two threads importing sklearn at once failed in CI with Python's import _DeadlockError
    # (sklearn -> narwhals, whose modules import each other): the study's thread imports it first.
    import subprocess
    import sys

    code = ("import sys; from motorlab.kinds.synergies import FIT, VAF\n"
            "assert 'sklearn' not in sys.modules\n"
            "FIT.warm_up(); VAF.warm_up()\n"
            "assert {'sklearn.decomposition', 'sklearn.preprocessing', 'narwhals'} <= set(sys.modules)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_a_demo_recipe_says_so_with_its_findings(registered, tmp_path):
    """A quick or demo recipe's `demo` line reaches every place its findings are read: results.json,
    report.html (above the findings), the printed summary and the Python API's Study; a full
    study's, and a results.json written before the field existed, have none."""
    import io

    from motorlab.api.views import load
    from motorlab.report.results import DEMO_LABEL, read_study_results

    why = "one seed & tiny budgets: it shows the pipeline"
    recipe = RECIPE.format(value=3) + '[[findings]]\nstep = "b"\nkey = "result"\n'
    printed = io.StringIO()
    run_study(parse_recipe(f'demo = "{why}"\n' + recipe, "doubling.toml"), tmp_path / "demo",
              console=Console(file=printed, width=200))
    assert json.loads((tmp_path / "demo" / "results.json").read_text())["demo"] == why
    assert read_study_results(tmp_path / "demo").demo == why
    report = (tmp_path / "demo" / "report.html").read_text()
    findings = report[report.index('<section class="findings">'):]
    assert findings.index(f"{DEMO_LABEL}:") < findings.index('<table class="findings">')
    assert "one seed &amp; tiny budgets: it shows the pipeline" in findings  # escaped: a recipe's text is no markup
    assert f"{DEMO_LABEL}: {why}" in printed.getvalue()
    study = load(tmp_path / "demo")
    assert study.demo == why and study._rows()[0] == (DEMO_LABEL, why)
    assert DEMO_LABEL in study._repr_html_() and why in repr(study)

    run_study(parse_recipe(recipe, "doubling.toml"), tmp_path / "full", console=quiet())
    assert json.loads((tmp_path / "full" / "results.json").read_text())["demo"] is None
    assert DEMO_LABEL not in (tmp_path / "full" / "report.html").read_text() and load(tmp_path / "full").demo is None
    older = json.loads((tmp_path / "full" / "results.json").read_text())
    del older["demo"]
    (tmp_path / "full" / "results.json").write_text(json.dumps(older))
    results = read_study_results(tmp_path / "full")
    assert results is not None and results.demo is None and [f.key for f in results.findings] == ["result"]


def test_a_demo_line_is_text():
    with pytest.raises(MotorlabError, match="field 'demo'"):
        parse_recipe('demo = ""\n' + RECIPE.format(value=3), "doubling.toml")
    with pytest.raises(MotorlabError, match="field 'demo'"):
        parse_recipe("demo = 5\n" + RECIPE.format(value=3), "doubling.toml")
