"""docs/hooks/benchmark_table.py, the MkDocs hook that writes docs/benchmarks.md's table of recorded
results: every fact it shows is its JSON's value, and a benchmark without a result file reads "not
yet run"."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from tests.helpers import docs_hook

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.fast




table = docs_hook("benchmark_table")
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


def _row(rendered: str, name: str) -> str:
    return next(line for line in rendered.splitlines() if f"`{name}`" in line)


def test_a_result_without_its_command_line_or_date_says_so(tmp_path):
    data = json.loads((RESULTS / "sar_robot.json").read_text())
    assert isinstance(data["argv"], list) and data["date"]
    (tmp_path / "sar_robot.json").write_text(json.dumps(data))
    row = _row(table.render(tmp_path), "sar_robot.json")
    assert f"`benchmarks/sar_robot.py {' '.join(data['argv'])}`" in row and data["date"][:10] in row
    assert table.NO_COMMAND not in row and table.UNDATED not in row
    del data["argv"], data["date"]
    (tmp_path / "sar_robot.json").write_text(json.dumps(data))
    row = _row(table.render(tmp_path), "sar_robot.json")
    assert table.NO_COMMAND in row and table.UNDATED in row
    # the recorded files that lack them (written before every script used provenance.Recorder)
    rendered = table.render(RESULTS)
    for path in RESULTS.glob("*.json"):
        recorded = json.loads(path.read_text())
        row = _row(rendered, path.name)
        assert (table.NO_COMMAND in row) == ("argv" not in recorded), path.name
        assert (table.UNDATED in row) == ("date" not in recorded), path.name


def test_statistics_over_seeds_are_computed_now_not_copied_from_the_stored_text(tmp_path):
    """A file whose stored labels are stale (a "95% CI" from 3 seeds, P = 0.5 "do not overlap" for tied
    seeds): the row shows what motorlab.intervals says of its per-seed values today."""
    from motorlab.intervals import across_seeds, p_better

    data = json.loads((RESULTS / "sar_robot.json").read_text())
    data["sar_rl"] = {"per_seed": [0.0, 0.0, 0.0], "value": 0.0, "ci95": [0.0, 0.0],
                      "ci_method": "95% stratified-bootstrap CI over 3 seeds"}
    data["rl_e2e"] = {"per_seed": [-1.0, 2.0, 5.0], "value": 2.0, "ci95": [-1.0, 5.0],
                      "ci_method": "95% stratified-bootstrap CI over 3 seeds"}
    data["p_sar_better"] = {"p": 0.5, "ci": None, "seeds": [3, 3],
                            "method": "no interval: every bootstrap resample gives the same P (the two sides' "
                                      "seeds do not overlap)"}
    (tmp_path / "sar_robot.json").write_text(json.dumps(data))
    row = _row(table.render(tmp_path), "sar_robot.json")
    assert "95% stratified-bootstrap CI over 3 seeds" not in row and "do not overlap" not in row
    assert across_seeds([-1.0, 2.0, 5.0]).text(table.results.FORMS["number"]) in row
    assert p_better([0.0, 0.0, 0.0], [-1.0, 2.0, 5.0]).text().replace("P(A > B)", "P(SAR-RL > RL-E2E)") in row


def test_steps_and_their_ratio_are_recomputed_from_the_per_seed_records(tmp_path):
    from motorlab.stats import steps_ratio, steps_to_threshold

    data = json.loads((RESULTS / "mbrl-pendulum.json").read_text())
    loop, sac = ([s["steps"] if not s["censored"] else None for s in data[k]["steps_to_threshold"]["per_seed"]]
                 for k in ("loop", "sac"))
    data["loop"]["steps_to_threshold"]["text"] = "stale"
    data["ratio_sac_over_loop"]["text"] = "stale too"
    (tmp_path / "mbrl-pendulum.json").write_text(json.dumps(data))
    row = _row(table.render(tmp_path), "mbrl-pendulum.json")
    a = steps_to_threshold(loop, data["loop"]["steps_to_threshold"]["budgets"])
    b = steps_to_threshold(sac, data["sac"]["steps_to_threshold"]["budgets"])
    assert "stale" not in row and a.text in row and b.text in row and steps_ratio(a, b).text in row


def test_every_benchmark_script_records_its_command_line_and_date():
    """Each script writes its result through benchmarks/provenance.py's Recorder (directly, or through
    the Harness of a science benchmark), which adds the date and the command line: none writes a
    result file of its own making."""
    scripts = table.scripts()
    assert len(scripts) >= 15
    for script in scripts:
        source = (table.BENCHMARKS / f"{script}.py").read_text()
        assert re.search(r"\b(Recorder|Harness)\(", source), f"benchmarks/{script}.py records no provenance"


def test_a_science_result_without_a_headline_record_is_marked_in_sample():
    provenance_note = table.provenance_note
    old = {"benchmark": "mbrl", "loop": {}}  # recorded before the harness: on the seeds the settings were chosen on
    assert provenance_note("mbrl", old).startswith("**in-sample**")
    headline = {"provenance": {"mode": "headline", "seeds": [100, 101, 102, 103, 104],
                               "development": {"configurations_tried": 6, "log": "benchmarks/devlog/mbrl-pusher.jsonl"}}}
    note = provenance_note("mbrl", headline)
    assert "100–104" in note and "6 configuration(s)" in note and not note.startswith("**in-sample**")
    assert "no development run" in note  # no run of these settings in the log: said so, with the last one
    headline["provenance"]["development"]["in_sample"] = [
        {"seeds": [0, 1, 2, 3, 4], "result": {"loop": {"steps_to_threshold": {"text": "5 of 5 seeds; median 600"}}}}]
    assert "in-sample with these settings (1 run(s), seeds [0, 1, 2, 3, 4]): loop 5 of 5 seeds; median 600" in \
        provenance_note("mbrl", headline)  # beside the held-out numbers, so a reader sees how they differ
    assert provenance_note("tune", old) == ""  # a speed or tuning benchmark has no development seeds to mark


def test_the_bodies_row_shows_each_methods_share_of_the_gap_and_its_in_sample_runs():
    """mbrl_bodies' row: per method the median share of the random-to-oracle gap, k of n bodies at the
    target and whether the target was met; a headline's in-sample runs are shown the same way."""
    targets = {m: {"median": share, "k": k, "of": 10, "met": k >= 8}
               for m, share, k in (("loop", 0.62, 3), ("mpc_user", 0.88, 10), ("mpc_learned", 0.71, 9))}
    data = {"benchmark": "mbrl_bodies", "targets": targets}
    shown = "; ".join(f.text(data) for f in table.facts("mbrl_bodies", data))
    assert "loop: median share of the random-to-oracle gap 62%; bodies at its target, of 10: 3" in shown
    assert "one-shot, user's reward: median share of the random-to-oracle gap 88%" in shown
    assert "loop met: **no**" in shown and "mpc_user met: yes" in shown
    dev = {"in_sample": [{"seeds": [0, 1], "result": {"targets": targets}}]}
    assert "loop median 62% of the gap (3 of 10 at its target)" in table.in_sample(dev)
