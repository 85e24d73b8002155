"""benchmarks/sar_hand_scaled.py's own logic: the scale that fits the hour, the recipe fields it sets
(equal env steps for both arms, the seeds, the learner), and the zero-shot table it reads."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import sar_hand_scaled as shs  # noqa: E402

pytestmark = pytest.mark.fast


@settings(max_examples=100, deadline=None, derandomize=True, database=None)
@given(rate=st.floats(5, 5000), seeds=st.integers(5, 10))
def test_the_scale_is_the_smallest_that_fits_the_hour(rate, seeds):
    k = shs.scale_for(rate, seeds)
    steps = shs.STUDY_STEPS["play"] + seeds * (shs.STUDY_STEPS["sar-rl"] + shs.STUDY_STEPS["rl-e2e"])
    budget = rate * 2 * 3600 * (1 - shs.OVERHEAD)
    assert steps / k <= budget + 1e-6  # fits
    assert k == 1 or steps / (k - 1) > budget  # and one step less would not


@pytest.mark.parametrize(("preset", "off_policy"), [("sar-sac", True), ("sar-ppo", False), ("sar-crossq", True)])
def test_both_arms_get_equal_env_steps_and_the_learner_its_own_settings(preset, off_policy):
    g = shs.given_fields(preset, 20, [100, 101, 102, 103, 104])
    assert g["rl-e2e.timesteps"] == g["play.timesteps"] + g["sar-rl.timesteps"] == (1_000_000 + 1_500_000) // 20
    assert g["sar-rl.seeds"] == g["rl-e2e.seeds"] == [100, 101, 102, 103, 104] and g["play.seed"] == 100
    assert g["preset"] == preset
    assert ("sar-rl.hyperparams" in g) == (not off_policy)  # PPO takes no learning_starts
    from motorlab.recipes import load_recipe

    recipe = load_recipe(shs.RECIPE, g)  # the fields are the recipe's: it loads and validates
    steps = {s.name: s for s in recipe.steps}
    assert steps["sar-rl"].seeds == [100, 101, 102, 103, 104]
    assert steps["rl-e2e"].settings.timesteps == g["rl-e2e.timesteps"] and steps["play"].settings.preset == preset


def test_an_unknown_learner_is_refused():
    with pytest.raises(SystemExit, match="unknown preset"):
        shs.given_fields("sar-nonsense", 20, [100])


def test_zero_shot_success_per_arm_seed_and_env(tmp_path):
    (tmp_path / "zeroshot").mkdir()
    (tmp_path / "zeroshot" / "summary.json").write_text(json.dumps({
        "sar-rl/seed100.myoHandReorientID-v0.success_rate": 0.4, "sar-rl/seed100.myoHandReorientOOD-v0.success_rate": 0.2,
        "rl-e2e/seed100.myoHandReorientID-v0.success_rate": 0.3, "sar-rl.myoHandReorientID-v0.success_rate_mean": 0.4,
        "sar-rl/seed100.myoHandReorientID-v0.return_mean": 5.0}))
    assert shs.zero_shot(tmp_path, "sar-rl") == {"myoHandReorientID-v0": {"seed100": 0.4},
                                                 "myoHandReorientOOD-v0": {"seed100": 0.2}}
    assert shs.zero_shot(tmp_path, "rl-e2e") == {"myoHandReorientID-v0": {"seed100": 0.3}}


def _recorded_run(folder: Path, learner: str) -> None:
    (folder / "sar_hand_scaled.json").write_text(json.dumps({
        "learner": learner, "seeds": [100, 101], "env_steps_per_seed": {"play": 1000, "sar-rl": 2000, "rl-e2e": 3000},
        "step_seconds": {"play": 10.0, "sar-rl": 40.0, "rl-e2e": 30.0}}))


def test_the_chain_rate_is_the_recorded_runs_slower_chain_for_the_same_learner(tmp_path):
    _recorded_run(tmp_path, "sar-sac-fast")
    # play -> SAR-RL: (1000 + 2 x 2000) / 50 s = 100/s; RL-E2E: 2 x 3000 / 30 s = 200/s
    assert shs.chain_rate(tmp_path, "sar-sac-fast", one_core=476.0) == pytest.approx(100.0)
    # another learner, or no recorded run: the one-core rate shared between the chains
    assert shs.chain_rate(tmp_path, "sar-sac", one_core=476.0) == pytest.approx(476.0 * shs.CHAINS_SHARE)
    assert shs.chain_rate(tmp_path / "nothing", "sar-sac-fast", one_core=476.0) == pytest.approx(476.0 * shs.CHAINS_SHARE)


def test_the_recorded_run_would_have_planned_a_smaller_study():
    """At the recorded run's own chain rate, the hour holds fewer env steps than the one-core rate promised."""
    results = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
    run = json.loads((results / "sar_hand_scaled.json").read_text())
    _, one_core = shs.recorded_winner(results)
    rate = shs.chain_rate(results, run["learner"], one_core)
    assert rate < one_core
    assert shs.scale_for(rate, len(run["seeds"])) >= shs.scale_for(one_core, len(run["seeds"]))
