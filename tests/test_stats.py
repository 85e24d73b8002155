"""Steps to a threshold over seeds (motorlab.stats): censoring at each seed's budget, the Kaplan-Meier
median, and the ratio of two medians with its bound. Every expected number is worked by hand below."""

from __future__ import annotations

import pytest

from motorlab.stats import steps_ratio, steps_to_threshold

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def test_km_median_with_two_seeds_censored_at_the_budget():
    # times: 1000, 1500, 2000 reached; two seeds censored at 3000 (never at the steps they collected).
    # KM survival S: 1000: 4/5 (F 0.2); 1500: 4/5 * 3/4 = 3/5 (F 0.4); 2000: 3/5 * 2/3 = 2/5 (F 0.6 >= 0.5).
    r = steps_to_threshold([1000, 2000, None, 1500, None], 3000)
    assert r.median == 2000.0
    assert (r.solved, r.seeds, r.budgets, r.median_above) == (3, 5, (3000,) * 5, None)
    assert [(s.steps, s.censored, s.time) for s in r.per_seed] == [
        (1000, False, 1000), (2000, False, 2000), (None, True, 3000), (1500, False, 1500), (None, True, 3000)]
    assert r.text == "3 of 5 seeds; median 2,000 steps (Kaplan–Meier)"


def test_none_solved_has_no_median():
    r = steps_to_threshold([None] * 5, 3000)
    assert r.median is None and r.median_above == 3000
    assert (r.solved, r.seeds) == (0, 5)
    assert r.text == "0 of 5 seeds; median > 3,000 (budget)"


def test_fewer_than_half_solved_is_above_the_budget():
    # 1000 reached, four censored at 3000: F(1000) = 0.2 and stays there
    r = steps_to_threshold([None, 1000, None, None, None], 3000)
    assert r.median is None and r.text == "1 of 5 seeds; median > 3,000 (budget)"


def test_all_solved_is_the_lower_median():
    # no censoring: F = 1/3, 2/3, 1 at 1000, 2000, 3000 -> 2000; with 4 seeds F(2000) = 2/4 -> 2000 (not 2500)
    assert steps_to_threshold([3000, 1000, 2000], 5000).median == 2000.0
    assert steps_to_threshold([4000, 1000, 3000, 2000], 5000).median == 2000.0


def test_ties_take_the_smallest_time_where_half_is_reached():
    # F(1000) = 2/4 = 0.5 exactly: the median is 1000 (numpy's median would say 1500)
    assert steps_to_threshold([1000, 1000, 2000, 2000], 3000).median == 1000.0
    # reached exactly at the budget counts as within it; ties of an event with censorings at 3000:
    # S(1000) = 3/4; at 3000 three at risk, one event: 3/4 * 2/3 = 1/2, F = 0.5 (a hair under in floats)
    r = steps_to_threshold([3000, None, None, 1000], 3000)
    assert r.median == 3000.0 and r.solved == 2


def test_a_seed_is_censored_at_its_own_budget():
    # seeds 2 and 3 had budgets 1100 and 1200 and never got there; the others had 4000.
    # times: 1000 reached (5 at risk: S 4/5); 1100 and 1200 censored (they leave the risk set);
    # 2000 reached with 2 at risk: S = 4/5 * 1/2 = 2/5, F = 0.6 -> median 2000.
    r = steps_to_threshold([1000, None, None, 2000, 3000], [4000, 1100, 1200, 4000, 4000])
    assert r.median == 2000.0
    assert [s.time for s in r.per_seed] == [1000, 1100, 1200, 2000, 3000]
    # censored (wrongly) at the largest budget they would stay at risk: S(2000) = 4/5 * 3/4 = 3/5 (F 0.4),
    # S(3000) = 3/5 * 2/3 = 2/5 (F 0.6) -> 3000
    assert steps_to_threshold([1000, None, None, 2000, 3000], 4000).median == 3000.0


def test_a_hit_past_the_budget_is_censored_at_the_budget():
    # a loop whose last round went past its 2000-step budget and reached the threshold at 2400
    r = steps_to_threshold([2400, 1000, None], 2000)
    assert [(s.steps, s.censored, s.time) for s in r.per_seed] == [(2400, True, 2000), (1000, False, 1000),
                                                                   (None, True, 2000)]
    assert r.solved == 1 and r.median is None  # F(1000) = 1/3
    assert r.text == "1 of 3 seeds; median > 2,000 (budget)"


def test_different_budgets_say_the_largest():
    r = steps_to_threshold([None, None], [1000, 3000])
    assert r.median_above == 3000 and r.text == "0 of 2 seeds; median > 3,000 (the largest budget)"


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        steps_to_threshold([], 1000)
    with pytest.raises(ValueError):
        steps_to_threshold([1, 2], [1000])
    with pytest.raises(ValueError):
        steps_to_threshold([0], 1000)


def test_ratio_bounds():
    loop = steps_to_threshold([1000, 1000, 2000], 3000)  # F(1000) = 2/3: median 1000
    loop_censored = steps_to_threshold([None, None, 2000], 3000)  # F(2000) = 1/3: median > 3000
    sac = steps_to_threshold([5000, 6000, 7000], 30_000)  # median 6000
    sac_censored = steps_to_threshold([None, None, 7000], 30_000)  # median > 30,000

    exact = steps_ratio(loop, sac)
    assert (exact.ratio, exact.bound, exact.text) == (6.0, "exact", "= 6")
    lower = steps_ratio(loop, sac_censored)  # SAC needs more than 30,000 / 1000 = 30 times the steps
    assert (lower.ratio, lower.bound, lower.numerator, lower.denominator) == (30.0, "lower", 30_000, 1000)
    assert lower.text == "> 30"
    upper = steps_ratio(loop_censored, sac)  # the loop's median > 3000: the ratio < 6000 / 3000 = 2
    assert (upper.ratio, upper.bound, upper.text) == (2.0, "upper", "< 2")
    unknown = steps_ratio(loop_censored, sac_censored)
    assert (unknown.ratio, unknown.bound) == (None, "unknown")
    assert unknown.to_json()["text"] == "unknown (both medians censored)"


def test_targets_on_censored_medians_and_ratios_are_met_unmet_or_open():
    solved = steps_to_threshold([1000, 1000, 2000], 3000)  # median 1000
    few = steps_to_threshold([None, None, 2000], 3000)  # median > 3000
    assert solved.at_most(1000) is True and solved.at_most(999) is False
    assert few.at_most(3000) is False  # above its budget, so above 3000
    assert few.at_most(5000) is None  # somewhere above 3000: 5000 or less is open
    sac = steps_to_threshold([5000, 6000, 7000], 30_000)
    sac_censored = steps_to_threshold([None, None, 7000], 30_000)
    assert steps_ratio(solved, sac).at_most(6) is True and steps_ratio(solved, sac).at_most(5.9) is False
    assert steps_ratio(few, sac).at_most(2) is True  # the ratio < 2
    assert steps_ratio(few, sac).at_most(1) is None
    assert steps_ratio(solved, sac_censored).at_most(30) is False  # the ratio > 30
    assert steps_ratio(solved, sac_censored).at_most(40) is None
    assert steps_ratio(few, sac_censored).at_most(1) is None
