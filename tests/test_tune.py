"""motorlab tune: Optuna search over settings, each trial judged on several seeds (issue 24)."""

from __future__ import annotations

import json

import pytest

from helpers import assert_one_line_error, run_cli

BASE = "train InvertedPendulum-v5 --preset fast --until-solved --timesteps 1500"  # LQR: solves in ~100 steps


@pytest.mark.parametrize("space, fragment", [
    ("lr=loguniform:0,1e-2", "must be positive"),
    ("lr=gauss:1,2", "unknown distribution"),
    ("lr=uniform:2,1", "LOW must be below HIGH"),
    ("n=int:1.5,3", "not integers"),
    ("n=choice:1", "at least two"),
    ("lr", "KEY=KIND:ARGS"),
])
def test_bad_space_is_one_line(tmp_path, space, fragment):
    assert_one_line_error(run_cli("tune", BASE, "--space", space, "--out", tmp_path / "t"), fragment)


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
