"""motorlab tune: Optuna search over settings, each trial judged on several seeds (issue 24)."""

from __future__ import annotations

import json

import pytest

from motorlab.errors import MotorlabError
from motorlab.tuning.space import parse_space
from tests.helpers import assert_one_line_error, run_cli, run_here

BASE = "train InvertedPendulum-v5 --preset fast --until-solved --timesteps 1500"  # LQR: solves in ~100 steps
# BASE judged on 2 evaluation episodes, not 10 (each of up to 1000 steps, after every model update): for
# searches whose trials need not run long (the pruning tests keep BASE, whose hopeless trials must outlast a poll)
QUICK = f"{BASE} --solve-episodes 2"


@pytest.mark.parametrize("space, fragment", [
    ("lr=loguniform:0,1e-2", "must be positive"),
    ("lr=gauss:1,2", "unknown distribution"),
    ("lr=uniform:2,1", "LOW must be below HIGH"),
    ("n=int:1.5,3", "not integers"),
    ("n=choice:1", "at least two"),
    ("lr", "KEY=KIND:ARGS"),
])
def test_bad_space_names_the_problem(space, fragment):
    with pytest.raises(MotorlabError, match=fragment):
        parse_space([space])


def test_bad_space_is_one_line_on_the_command_line(tmp_path):
    assert_one_line_error(run_here("tune", BASE, "--space", "lr=gauss:1,2", "--out", tmp_path / "t"),
                          "unknown distribution")
    assert not (tmp_path / "t" / "study.db").exists()


def test_unreachable_storage_is_one_line(tmp_path):
    proc = run_here("tune", BASE, "--space", "delay=uniform:0.05,0.2", "--storage", "sqlite:////no/such/dir/study.db",
                    "--out", tmp_path / "t")
    assert_one_line_error(proc, "storage")


def test_tiny_search_prunes_writes_best_toml_and_reproduces(tmp_path):
    out = tmp_path / "t"
    proc = run_cli("tune", QUICK, "--space", "solve_return=choice:1000,5000", "--space", "delay=uniform:0.05,0.2",
                   "--trials", "4", "--seeds", "2", "--prune-startup", "1", "--report-every", "100",
                   "--sampler", "random", "--out", out)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "study.db").is_file() and (out / "trials.csv").is_file()
    assert summary["n_trials"].get("complete", 0) + summary["n_trials"].get("pruned", 0) == 4
    assert len(summary["fresh_values"]) == 2
    best = summary["best_trial"]
    rerun = run_cli("train", "InvertedPendulum-v5", "--preset", "fast", "--until-solved", "--timesteps", "1500",
                    "--solve-episodes", "2", "--preset-file", out / "best.toml", "--seed", "0", "--out", tmp_path / "again")
    assert rerun.returncode == 0, rerun.stderr
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    trial_run = json.loads((out / "trials" / str(best) / "seed0" / "summary.json").read_text())
    assert again["steps_to_success"] == trial_run["steps_to_success"]
    _check_report(out, summary)


def _check_report(out, summary) -> None:
    """report.html opens in Chromium with nothing broken: the findings hold the best trial's and the
    fresh seeds' numbers, one row per trial, every figure loads, every internal link has a target."""
    from playwright.sync_api import sync_playwright

    from tests.report.test_html import CHROMIUM, Opened, _check_page

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
        try:
            opened = Opened(browser, out / "report.html")
            _check_page(opened)
            page = opened.page
            findings = page.eval_on_selector_all("table.findings tbody tr", "rs => rs.map(r => [r.dataset.step, "
                                                 "Number(r.querySelector('td.value').dataset.value)])")
            assert findings == [[f"trial-{summary['best_trial']}", pytest.approx(summary["best_value"])],
                                ["fresh", pytest.approx(summary["fresh_value"])]]
            rows = page.eval_on_selector_all("table.study tbody tr", "rs => rs.length")
            assert rows == sum(summary["n_trials"].values())
            broken = page.evaluate("() => Array.from(document.querySelectorAll('a[href^=\"#\"]'))"
                                   ".map(a => a.getAttribute('href').slice(1)).filter(id => !document.getElementById(id))")
            assert broken == []
            names = {p.name for p in (out / "plots").glob("*.png")}
            assert {"history.png", "slice-delay.png"} <= names
        finally:
            browser.close()


def _study(out):
    import optuna

    summary = json.loads((out / "summary.json").read_text())
    return optuna.load_study(study_name=summary["study_name"], storage=summary["storage"])


def test_pruning_stops_a_hopeless_trial(tmp_path):
    """solve_return 5000 can never be reached (the maximum return is 1000). --sampler-seed 6 samples
    1000, 1000, 5000: the third trial lags the median steps-to-success of the first two (solved in
    ~100 steps) from step 200 on, and is pruned long before its budget, its run left unfinished."""
    import optuna

    out = tmp_path / "t"
    proc = run_cli("tune", "train InvertedPendulum-v5 --preset fast --until-solved --timesteps 3000",
                   "--space", "solve_return=choice:1000,5000", "--trials", "3", "--seeds", "1", "--sampler", "random",
                   "--sampler-seed", "6", "--prune-startup", "1", "--report-every", "100", "--fresh-seeds", "0",
                   "--out", out)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    trials = _study(out).trials
    assert [t.params["solve_return"] for t in trials] == ["1000", "1000", "5000"]  # the seed's samples
    states = [t.state for t in trials]
    assert states == [optuna.trial.TrialState.COMPLETE] * 2 + [optuna.trial.TrialState.PRUNED]
    hopeless = trials[2]
    run = out / "trials" / "2" / "seed0"
    assert not (run / "summary.json").exists()  # stopped, not finished
    assert 0 < hopeless.user_attrs["env_steps"] < 3000
    assert hopeless.user_attrs["env_steps_saved"] == 3000 - hopeless.user_attrs["env_steps"]
    assert max(hopeless.intermediate_values) < 3000  # reported while it ran
    summary = json.loads((out / "summary.json").read_text())
    assert summary["env_steps_saved_by_pruning"] == hopeless.user_attrs["env_steps_saved"]
    assert summary["best_trial"] in (0, 1)
    _check_dashboard(summary["storage"], summary["study_name"])


def _check_dashboard(storage: str, name: str) -> None:
    """`optuna-dashboard STORAGE` (the line tune prints) serves the study."""
    import subprocess
    import sys
    import time
    import urllib.request
    from pathlib import Path

    from tests.helpers import free_port

    port = free_port()
    dashboard = str(Path(sys.executable).with_name("optuna-dashboard"))
    proc = subprocess.Popen([dashboard, storage, "--port", str(port), "--host", "127.0.0.1", "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.time() + 60
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/studies", timeout=5) as r:
                    studies = json.loads(r.read())["study_summaries"]
                break
            except OSError:
                assert proc.poll() is None and time.time() < deadline, proc.stderr.read().decode()
                time.sleep(0.5)
        assert [s["study_name"] for s in studies] == [name]
    finally:
        proc.terminate()
        proc.wait(timeout=30)


RECIPE = """name = "tiny"
description = "LQR balancing, one step"

[defaults]
env = "InvertedPendulum-v5"

[[steps]]
name = "lqr"
kind = "train"
preset = "fast"
timesteps = 1500
until_solved = true
solve_episodes = 2
"""


def test_a_recipe_is_tuned_by_its_step_fields_and_the_best_runs_as_a_recipe(tmp_path):
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(RECIPE)
    out = tmp_path / "t"
    proc = run_cli("tune", recipe, "--space", "lqr.delay=uniform:0.05,0.25", "--trials", "1", "--seeds", "1",
                   "--objective", "lqr.return_mean", "--pruner", "none", "--fresh-seeds", "0",
                   "--sampler-seed", "0", "--out", out)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    study = _study(out)
    for t in study.trials:  # each trial ran the whole study; its value is the study's number
        trial_summary = json.loads((out / "trials" / str(t.number) / "seed0" / "summary.json").read_text())
        assert t.value == pytest.approx(trial_summary["lqr.return_mean"])
        recipe_run = (out / "trials" / str(t.number) / "seed0" / "lqr" / "config.toml").read_text()
        assert f"delay = {float(t.params['lqr.delay'])!r}" in recipe_run
    best = json.loads((out / "summary.json").read_text())["best_trial"]
    import tomllib

    assert tomllib.loads((out / "best.toml").read_text()) == {"lqr": {"delay": float(
        study.trials[best].params["lqr.delay"])}}
    again = run_cli("run", out / "best_recipe.toml", "--out", tmp_path / "again")
    assert again.returncode == 0, again.stderr
    rerun = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert rerun["lqr.return_mean"] == pytest.approx(study.trials[best].value)


SEARCH = ["--space", "delay=uniform:0.05,0.2", "--seeds", "1", "--sampler", "random", "--pruner", "none",
          "--fresh-seeds", "0"]


def counted(out) -> tuple[int, list[int]]:
    """Trials that count (COMPLETE, PRUNED) in the study, and every trial number."""
    import optuna

    summary = json.loads((out / "summary.json").read_text())
    study = optuna.load_study(study_name=summary["study_name"], storage=summary["storage"])
    states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
    return sum(t.state in states for t in study.trials), [t.number for t in study.trials]


def test_two_processes_share_one_study_without_duplicates(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "t"
    argv = [sys.executable, "-m", "motorlab", "tune", QUICK, *SEARCH, "--trials", "3", "--out", str(out)]
    procs = [subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    for p in procs:
        _, stderr = p.communicate(timeout=300)
        assert p.returncode == 0, stderr
    n, numbers = counted(out)
    assert n == 3 and len(numbers) == len(set(numbers))  # three trials in all, none run twice
    # a trial that found three ahead of it (both processes asked at once) gave way before running anything
    ran = [t.number for t in _study(out).trials if not t.user_attrs.get("gave_way")]
    assert sorted(int(d.name) for d in (out / "trials").iterdir()) == ran


def test_an_interrupted_search_resumes_with_its_finished_trials(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "t"
    argv = [sys.executable, "-m", "motorlab", "tune", QUICK, *SEARCH, "--trials", "2", "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = out / "trials" / "0" / "seed0" / "summary.json"
    deadline = time.time() + 120
    while not first.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert first.exists()
    kept = first.stat().st_mtime_ns
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=120)
    assert proc.returncode != 0
    again = run_cli("tune", QUICK, *SEARCH, "--trials", "2", "--out", out)
    assert again.returncode == 0, again.stderr
    assert first.stat().st_mtime_ns == kept  # the finished trial was kept, not run again
    assert counted(out)[0] == 2


def test_unknown_objective_is_one_line(tmp_path):
    proc = run_cli("tune", QUICK, *SEARCH, "--trials", "1", "--objective", "no_such_key", "--out", tmp_path / "t")
    assert_one_line_error(proc, "no_such_key", "steps_to_success")


@pytest.mark.fast
def test_steps_objective_censors_unsolved_seeds_and_never_shows_the_budget_as_a_value():
    """Seeds solved at 800 and 1,600 steps, a third unsolved within its 3,000: the search compares
    the restricted mean ((800 + 1,600 + 3,000) / 3 = 1,800); people read "2 of 3 seeds" and the
    Kaplan-Meier median (1,600: the estimate reaches 2/3 there), the unsolved seed as "> 3,000"."""
    from motorlab.report.html import _finding
    from motorlab.tuning.objective import Objective
    from motorlab.tuning.outputs import Fresh, number, seeds_text

    objective = Objective.make("steps_to_success", None)
    summaries = [{"steps_to_success": 800, "timesteps": 800, "budget": 3000},
                 {"steps_to_success": 1600, "timesteps": 1600, "budget": 3000},
                 {"steps_to_success": None, "timesteps": 3000, "budget": 3000}]
    scores = [objective.score(s) for s in summaries]
    assert scores == [(800.0, False), (1600.0, False), (3000.0, True)]
    assert objective.combine([v for v, _ in scores]) == pytest.approx(1800.0)
    assert objective.statistic(3) == "restricted mean"
    assert objective.describe(scores, number) == (
        "2 of 3 seeds, 95% Wilson interval [21%, 94%]; median 1,600 steps (Kaplan–Meier), no interval "
        "(n = 3: too few seeds for a confidence interval, which needs 5); restricted mean 1,800")
    assert seeds_text(objective, scores) == "800, 1,600, > 3,000"
    fresh = Fresh([100, 101, 102], scores, objective).to_summary()
    assert (fresh["fresh_solved"], fresh["fresh_median"], fresh["fresh_ci"]) == (2, 1600.0, None)
    assert fresh["fresh_solved_ci"] == pytest.approx([0.2077, 0.9385], abs=1e-4)  # Wilson, 2 of 3
    assert fresh["fresh_median_ci"] is None and "too few seeds" in fresh["fresh_median_ci_method"]
    assert fresh["fresh_censored"] == [False, False, True]
    # fewer than half solved: no median, only a bound; the report's finding says so
    few = [(800.0, False), (3000.0, True), (3000.0, True)]
    assert objective.describe(few, number).startswith("1 of 3 seeds, 95% Wilson interval [6%, 79%]; "
                                                      "median > 3,000 (budget)")
    finding = _finding("steps", "fresh", "steps_to_success", 2266.7, ["seed0", "seed1", "seed2"],
                       [v for v, _ in few], [c for _, c in few])
    assert finding.values == ["800", "> 3,000", "> 3,000"]
    assert finding.aggregate.startswith("1 of 3 seeds, 95% Wilson interval") and finding.ci is None
    assert "median > 3,000 (budget)" in finding.aggregate
    # a return objective keeps the across-seed rule: the mean below 4 seeds, a CI from 5, the range below
    returns = Objective.make("final_return", None)
    assert returns.statistic(3) == "mean" and returns.statistic(4) == "IQM"
    two = Fresh([100, 101], [(10.0, False), (20.0, False)], returns).to_summary()
    assert two["fresh_ci"] is None and two["fresh_range"] == [10.0, 20.0]
    assert "range of 2 seeds" in two["fresh_ci_method"]
    five = Fresh(list(range(5)), [(float(v), False) for v in (10, 20, 30, 40, 50)], returns).to_summary()
    assert 10.0 <= five["fresh_ci"][0] < five["fresh_ci"][1] <= 50.0
    assert five["fresh_ci_method"] == "95% stratified-bootstrap CI over 5 seeds"


def test_a_search_records_no_credential_of_its_target(tmp_path):
    """A credential in the target (here an ignored LQR hyperparameter) is in none of the files the search
    writes: config.toml, summary.json, best.toml (its header quotes the target), table.txt, report.html, the
    trials' run folders (the job files excepted: a trial's process needs its settings as given)."""
    out = tmp_path / "t"
    target = f"{QUICK} --set note=postgresql://me:s3cretpw@db/x"
    proc = run_cli("tune", target, *SEARCH, "--trials", "1", "--out", out)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    assert "me:***@db" in (out / "best.toml").read_text() and "me:***@db" in (out / "config.toml").read_text()
    for path in out.rglob("*"):
        if path.is_file() and not path.name.endswith(".job.json") and path.name != "study.db":
            assert b"s3cretpw" not in path.read_bytes(), path
