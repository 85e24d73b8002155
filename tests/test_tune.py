"""motorlab tune: Optuna search over settings, each trial judged on several seeds (issue 24)."""

from __future__ import annotations

import json

import pytest

from helpers import assert_one_line_error, run_cli
from motorlab.errors import MotorlabError
from motorlab.tuning.space import parse_space

BASE = "train InvertedPendulum-v5 --preset fast --until-solved --timesteps 1500"  # LQR: solves in ~100 steps


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
    assert_one_line_error(run_cli("tune", BASE, "--space", "lr=gauss:1,2", "--out", tmp_path / "t"),
                          "unknown distribution")
    assert not (tmp_path / "t" / "study.db").exists()


def test_unreachable_storage_is_one_line(tmp_path):
    proc = run_cli("tune", BASE, "--space", "delay=uniform:0.05,0.2", "--storage", "sqlite:////no/such/dir/study.db",
                   "--out", tmp_path / "t")
    assert_one_line_error(proc, "storage")


def test_tiny_search_prunes_writes_best_toml_and_reproduces(tmp_path):
    out = tmp_path / "t"
    proc = run_cli("tune", BASE, "--space", "solve_return=choice:1000,5000", "--space", "delay=uniform:0.05,0.2",
                   "--trials", "4", "--seeds", "2", "--prune-startup", "1", "--report-every", "100",
                   "--sampler", "random", "--out", out)
    assert proc.returncode == 0, proc.stderr + proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert (out / "study.db").is_file() and (out / "trials.csv").is_file()
    assert summary["n_trials"].get("complete", 0) + summary["n_trials"].get("pruned", 0) == 4
    assert len(summary["fresh_values"]) == 2
    best = summary["best_trial"]
    rerun = run_cli("train", "InvertedPendulum-v5", "--preset", "fast", "--until-solved", "--timesteps", "1500",
                    "--preset-file", out / "best.toml", "--seed", "0", "--out", tmp_path / "again")
    assert rerun.returncode == 0, rerun.stderr
    again = json.loads((tmp_path / "again" / "summary.json").read_text())
    trial_run = json.loads((out / "trials" / str(best) / "seed0" / "summary.json").read_text())
    assert again["steps_to_success"] == trial_run["steps_to_success"]


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
    argv = [sys.executable, "-m", "motorlab", "tune", BASE, *SEARCH, "--trials", "3", "--out", str(out)]
    procs = [subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    for p in procs:
        _, stderr = p.communicate(timeout=300)
        assert p.returncode == 0, stderr
    n, numbers = counted(out)
    assert n == 3 and len(numbers) == len(set(numbers))  # three trials in all, none run twice
    assert len(list((out / "trials").iterdir())) == len(numbers)


def test_an_interrupted_search_resumes_with_its_finished_trials(tmp_path):
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "t"
    argv = [sys.executable, "-m", "motorlab", "tune", BASE, *SEARCH, "--trials", "2", "--out", str(out)]
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
    again = run_cli("tune", BASE, *SEARCH, "--trials", "2", "--out", out)
    assert again.returncode == 0, again.stderr
    assert first.stat().st_mtime_ns == kept  # the finished trial was kept, not run again
    assert counted(out)[0] == 2


def test_unknown_objective_is_one_line(tmp_path):
    proc = run_cli("tune", BASE, *SEARCH, "--trials", "1", "--objective", "no_such_key", "--out", tmp_path / "t")
    assert_one_line_error(proc, "no_such_key", "steps_to_success")
