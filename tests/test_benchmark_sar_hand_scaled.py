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
