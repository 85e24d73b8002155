"""Steps-to-success: --until-solved stops at the first consistently solving policy;
an unsolved run reports null."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from motorlab.envs import EnvConfig
from motorlab.evaluation import evaluate
from motorlab.policies import load_policy, load_run_policy
from motorlab.rl.config import resolve
from motorlab.rl.monitor import EVAL_SEED_OFFSET, TrainingMonitor
from tests.helpers import ENV_ID, TINY_PPO, assert_ok, read_summary, run_cli

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def test_fast_preset_until_solved_stops_early(fast_run):
    s = read_summary(fast_run)
    assert s["algo"] == "lqr" and s["preset"] == "fast"
    assert isinstance(s["steps_to_success"], int)
    assert s["steps_to_success"] == s["timesteps"]  # stopped as soon as it was solved
    assert 0 < s["timesteps"] < s["budget"] == 3000
    assert s["solved"] is True
    assert s["eval_return_min"] == 1000.0 and s["eval_success_rate"] == 1.0
    # The saved controller really is the solving one: it reaches the maximum on fresh seeds too.
    result = evaluate(load_run_policy(fast_run), EnvConfig(), episodes=3, seed=99)
    np.testing.assert_array_equal(result.returns, 1000.0)


def test_fast_preset_metrics_record_the_solving_evaluation(fast_run):
    with open(fast_run / "metrics.csv", newline="") as f:
        evals = [r for r in csv.DictReader(f) if r["eval_return_mean"]]
    sts = read_summary(fast_run)["steps_to_success"]
    solving = [r for r in evals if float(r["eval_success_rate"]) == 1.0]
    assert solving and int(solving[0]["timesteps"]) == sts
    assert all(float(r["eval_success_rate"]) < 1.0 for r in evals if int(r["timesteps"]) < sts)


def test_unsolved_ppo_reports_null_steps_to_success(tmp_path):
    out = tmp_path / "ppo-until"
    assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--until-solved", "--no-progress", "--out", out))
    text = (out / "summary.json").read_text()
    assert '"steps_to_success": null' in text  # JSON null, not 0, NaN or a string
    s = json.loads(text)
    assert s["steps_to_success"] is None
    assert s["solved"] is False
    assert s["until_solved"] is True
    assert s["timesteps"] == s["budget"] == 256  # the whole budget was used


def _monitor(tmp_path, **settings) -> TrainingMonitor:
    cfg = resolve({"until_solved": True, "solve_episodes": 2, "timesteps": 1000, **settings})
    return TrainingMonitor(cfg, tmp_path, solve_return=1000.0)


def test_tracker_solved_from_the_start(tmp_path):
    monitor = _monitor(tmp_path)
    try:
        pid = load_policy("pid", monitor.evaluator.envs[0], ENV_ID)
        assert monitor.evaluate(50, pid) is True
        assert monitor.steps_to_success == 50
        assert monitor.evaluate(80, pid) is True
        assert monitor.steps_to_success == 50  # the first solving evaluation counts
        assert monitor.evaluations == 2 and monitor.last_eval_steps == 80
        assert monitor.evaluator.seed == EVAL_SEED_OFFSET  # evaluation seeds never overlap training seeds
    finally:
        monitor.close()
    with open(tmp_path / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["timesteps"]) for r in rows] == [50, 80]
    assert all(float(r["eval_success_rate"]) == 1.0 and float(r["eval_return_min"]) == 1000.0 for r in rows)


def test_tracker_never_solved(tmp_path):
    monitor = _monitor(tmp_path)
    try:
        zero = load_policy("zero", monitor.evaluator.envs[0], ENV_ID)
        for steps in (100, 200, 300):
            assert monitor.evaluate(steps, zero) is False
        assert monitor.steps_to_success is None
        assert monitor.evaluations == 3
    finally:
        monitor.close()


def test_tracker_solved_later(tmp_path):
    monitor = _monitor(tmp_path)
    try:
        env = monitor.evaluator.envs[0]
        assert monitor.evaluate(100, load_policy("zero", env, ENV_ID)) is False
        assert monitor.evaluate(200, load_policy("pid", env, ENV_ID)) is True
        assert monitor.evaluate(300, load_policy("zero", env, ENV_ID)) is False
        assert monitor.steps_to_success == 200
    finally:
        monitor.close()


def test_tracker_without_target_never_solves(tmp_path):
    cfg = resolve({"solve_episodes": 2, "timesteps": 1000})
    monitor = TrainingMonitor(cfg, tmp_path, solve_return=None)
    try:
        assert monitor.evaluate(10, load_policy("pid", monitor.evaluator.envs[0], ENV_ID)) is False
        assert monitor.steps_to_success is None
    finally:
        monitor.close()


@pytest.mark.parametrize("solve_return, solved", [(500.0, True), (1000.0, True), (1001.0, False)])
def test_tracker_uses_solve_return(tmp_path, solve_return, solved):
    cfg = resolve({"until_solved": True, "solve_episodes": 2, "timesteps": 1000})
    monitor = TrainingMonitor(cfg, tmp_path, solve_return=solve_return)
    try:
        assert monitor.evaluate(10, load_policy("pid", monitor.evaluator.envs[0], ENV_ID)) is solved
    finally:
        monitor.close()
