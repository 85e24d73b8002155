"""benchmarks/mbrl.py's own logic: seeds split into development and headline, SAC's tuned variant
read from the search's file, the returns at fixed budgets."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import mbrl  # noqa: E402

pytestmark = pytest.mark.fast


def test_seed_lists_and_the_default_headline_seeds():
    assert mbrl.seed_list("100-104") == [100, 101, 102, 103, 104] == mbrl.HEADLINE_SEEDS
    assert mbrl.seed_list("3,1-2,3") == [3, 1, 2]
    assert mbrl.parse(["reacher"]).seeds == mbrl.HEADLINE_SEEDS


def test_a_mix_of_development_and_headline_seeds_is_refused_before_any_work():
    with pytest.raises(SystemExit, match="mix development seeds"):
        mbrl.parse(["reacher", "--seeds", "4,100"])
    with pytest.raises(SystemExit):
        mbrl.parse(["reacher", "--sac", "tuned,zoo"])


def test_the_tuned_variant_needs_the_searchs_file(tmp_path, monkeypatch):
    monkeypatch.setattr(mbrl, "TUNED", tmp_path / "sac_tuned.json")
    with pytest.raises(SystemExit, match="sac_tune.py"):
        mbrl.tuned_params("Reacher-v5")
    (tmp_path / "sac_tuned.json").write_text('{"Reacher-v5": {"params": {"gamma": 0.98}}}')
    assert mbrl.tuned_params("Reacher-v5") == {"gamma": 0.98}


def test_returns_at_fixed_budgets_take_the_last_evaluation_at_or_before_each():
    curve = [{"env_steps": 200, "return_mean": -20.0}, {"env_steps": 1000, "return_mean": -9.0},
             {"env_steps": 1200, "return_mean": -4.0}]
    at = mbrl.returns_at(curve, [100, 1000, 3000])
    assert at["100"] == {"return_mean": None, "carried_from_stop": False}  # no evaluation yet
    assert at["1000"] == {"return_mean": -9.0, "carried_from_stop": False}
    assert at["3000"] == {"return_mean": -4.0, "carried_from_stop": True}  # stopped at 1,200: carried, and said


def test_sac_is_evaluated_as_often_as_the_loop_evaluates():
    assert mbrl.eval_interval("reacher", 3000, {}) == 200  # 4 episodes of 50 steps a round
    assert mbrl.eval_interval("arm", 3000, {}) == 150  # one 150-step episode a round


def test_a_tune_at_another_budget_is_its_own_study():
    """sac_tune.py resumes the study of its --steps and --seeds only: trials scored at 5k and at 15k
    env steps never share a study (or a best trial)."""
    import sac_tune

    steps, seeds = sac_tune.DEFAULT_BUDGET
    assert sac_tune.parse(["cartpole"]).steps == steps and tuple(sac_tune.parse(["cartpole"]).seeds) == seeds
    assert sac_tune.study_name("cartpole", steps, list(seeds)) == "sac-cartpole"  # the first searches' name
    names = {sac_tune.study_name("cartpole", n, s) for n in (5_000, 15_000) for s in ([0, 1], [0, 1, 2])}
    assert len(names) == 4
