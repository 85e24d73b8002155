"""--minutes (a wall-clock budget of training) and --eval-every-minutes: learners of different speeds
meet the same minutes, evaluations not counted against them."""

from __future__ import annotations

import csv

import pytest

from motorlab.errors import MotorlabError
from motorlab.rl.config import resolve
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_cli


def test_minutes_stop_training_and_evaluations_follow_the_training_clock(tmp_path):
    out = tmp_path / "sac"
    budget_s = 4.0
    assert_ok(run_cli("train", ENV_ID, "--algo", "sac", "--timesteps", "1000000", "--minutes", str(budget_s / 60),
                      "--eval-every-minutes", str(1 / 60), "--solve-episodes", "2", "--no-progress",
                      "--set", "learning_starts=100", "--out", out))
    s = read_summary(out)
    assert s["stopped_by"] == "minutes" and s["minutes"] == pytest.approx(budget_s / 60)
    assert 0 < s["timesteps"] < s["budget"]
    # training stops at the first step past the budget: one SAC step is milliseconds
    assert budget_s <= s["train_seconds"] < budget_s + 1.0
    assert s["wall_seconds"] > s["train_seconds"]  # the evaluations took time that was not counted
    with open(out / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    evals = [float(r["train_seconds"]) for r in rows if r["eval_return_mean"]]
    # one evaluation per second of training (the last one at the end), each at or just past its mark
    assert len(evals) >= 4
    for mark, at in zip(range(1, 4), evals):
        assert mark <= at < mark + 0.5
    trained = [float(r["train_seconds"]) for r in rows]
    assert trained == sorted(trained)  # the training clock never runs back
    assert all(float(r["train_seconds"]) <= float(r["wall_seconds"]) for r in rows)


def test_the_step_budget_still_ends_a_run_that_has_minutes_to_spare(tmp_path):
    out = tmp_path / "sac"
    assert_ok(run_cli("train", ENV_ID, "--algo", "sac", "--timesteps", "300", "--minutes", "10",
                      "--solve-episodes", "2", "--no-progress", "--set", "learning_starts=100", "--out", out))
    s = read_summary(out)
    assert s["stopped_by"] == "timesteps" and s["timesteps"] == 300


def test_two_evaluation_clocks_are_refused_in_one_line(tmp_path):
    with pytest.raises(MotorlabError, match="give one of them"):
        resolve({"eval_every": 1000, "eval_every_minutes": 1.0})
    assert_one_line_error(run_cli("train", ENV_ID, "--eval-every", "100", "--eval-every-minutes", "1",
                                  "--out", tmp_path / "x"), "give one of them")
    assert not (tmp_path / "x").exists()
