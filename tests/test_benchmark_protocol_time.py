"""benchmarks/protocol_time.py: a study's training hours from a recorded rate, read from the recipe's own
budgets, on one machine and on a Ray cluster of N."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import protocol_time as pt  # noqa: E402

pytestmark = pytest.mark.fast


def test_the_hand_protocols_budgets_are_the_recipes():
    assert pt.train_budgets("sar-hand-reference") == (("play", 1_000_000, 1), ("sar-rl", 1_500_000, 5),
                                                       ("rl-e2e", 2_500_000, 5))


def test_one_machine_runs_every_seed_in_turn_and_five_run_a_steps_seeds_at_once():
    # 1M + 5 x 1.5M + 5 x 2.5M = 21M env steps on one machine; 1M + 1.5M + 2.5M = 5M on five
    assert pt.training_hours("sar-hand-reference", 1000.0, 1) == pytest.approx(21_000_000 / 1000 / 3600)
    assert pt.training_hours("sar-hand-reference", 1000.0, 5) == pytest.approx(5_000_000 / 1000 / 3600)
    assert pt.training_hours("sar-hand-reference", 1000.0, 2) == pytest.approx(13_000_000 / 1000 / 3600)  # 3 rounds


@settings(max_examples=50, deadline=None)
@given(rate=st.floats(1.0, 1e5), machines=st.integers(1, 12))
def test_more_machines_never_take_longer_and_the_rate_scales_the_time(rate, machines):
    hours = pt.training_hours("sar-hand-reference", rate, machines)
    assert hours <= pt.training_hours("sar-hand-reference", rate, max(1, machines - 1)) + 1e-12
    assert pt.training_hours("sar-hand-reference", 2 * rate, machines) == pytest.approx(hours / 2)
    rounds = math.ceil(5 / machines)  # beyond five machines, one seed each: the path is a seed per step
    assert hours * rate * 3600 == pytest.approx(1_000_000 + rounds * 4_000_000)


@pytest.mark.parametrize(("rate", "machines"), [(0.0, 1), (-3.0, 2), (float("nan"), 1), (10.0, 0)])
def test_no_rate_or_no_machine_is_refused(rate, machines):
    with pytest.raises(ValueError, match="a rate > 0 and at least one machine"):
        pt.training_hours("sar-hand-reference", rate, machines)
