"""Steps to a threshold over seeds (motorlab.stats): censoring at each seed's budget, the Kaplan-Meier
median, and the ratio of two medians with its bound; k of n's Wilson interval, and the bootstrap
intervals of the median and of the ratio. Every expected median is worked by hand below."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binomtest

from motorlab.stats import _km_median, _median_draws, steps_ratio, steps_to_threshold

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level


def test_km_median_with_two_seeds_censored_at_the_budget():
    # times: 1000, 1500, 2000 reached; two seeds censored at 3000 (never at the steps they collected).
    # KM survival S: 1000: 4/5 (F 0.2); 1500: 4/5 * 3/4 = 3/5 (F 0.4); 2000: 3/5 * 2/3 = 2/5 (F 0.6 >= 0.5).
    r = steps_to_threshold([1000, 2000, None, 1500, None], 3000)
    assert r.median == 2000.0
    assert (r.solved, r.seeds, r.budgets, r.median_above) == (3, 5, (3000,) * 5, None)
    assert [(s.steps, s.censored, s.time) for s in r.per_seed] == [
        (1000, False, 1000), (2000, False, 2000), (None, True, 3000), (1500, False, 1500), (None, True, 3000)]
    assert r.text.startswith("3 of 5 seeds, 95% Wilson interval [23%, 88%]; median 2,000 steps (Kaplan–Meier), "
                             "95% bootstrap CI over 5 seeds [")


def test_none_solved_has_no_median():
    r = steps_to_threshold([None] * 5, 3000)
    assert r.median is None and r.median_above == 3000
    assert (r.solved, r.seeds) == (0, 5)
    assert r.text.startswith("0 of 5 seeds, 95% Wilson interval [0%, 43%]; median > 3,000 (budget), ")


def test_fewer_than_half_solved_is_above_the_budget():
    # 1000 reached, four censored at 3000: F(1000) = 0.2 and stays there
    r = steps_to_threshold([None, 1000, None, None, None], 3000)
    assert r.median is None
    assert r.text.startswith("1 of 5 seeds, 95% Wilson interval [4%, 62%]; median > 3,000 (budget)")


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
    assert r.text == ("1 of 3 seeds, 95% Wilson interval [6%, 79%]; median > 2,000 (budget), no interval "
                      "(n = 3: too few seeds for a confidence interval, which needs 5)")


def test_different_budgets_say_the_largest():
    r = steps_to_threshold([None, None], [1000, 3000])
    assert r.median_above == 3000
    assert "0 of 2 seeds, 95% Wilson interval [0%, 66%]; median > 3,000 (the largest budget)" in r.text


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
    assert (exact.ratio, exact.bound, exact.ci) == (6.0, "exact", None)  # 3 seeds a side: no interval
    assert exact.text == "= 6, no interval: n = 3 and 3 seeds, too few for one, which needs 5 a side"
    lower = steps_ratio(loop, sac_censored)  # SAC needs more than 30,000 / 1000 = 30 times the steps
    assert (lower.ratio, lower.bound, lower.numerator, lower.denominator) == (30.0, "lower", 30_000, 1000)
    assert lower.text.startswith("> 30, ")
    upper = steps_ratio(loop_censored, sac)  # the loop's median > 3000: the ratio < 6000 / 3000 = 2
    assert (upper.ratio, upper.bound) == (2.0, "upper") and upper.text.startswith("< 2, ")
    unknown = steps_ratio(loop_censored, sac_censored)
    assert (unknown.ratio, unknown.bound) == (None, "unknown")
    assert unknown.to_json()["text"].startswith("unknown (both medians censored), no interval")


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


def test_k_of_n_has_scipys_wilson_interval():
    r = steps_to_threshold([1000, 2000, None, 1500, None], 3000)
    expected = binomtest(3, 5).proportion_ci(confidence_level=0.95, method="wilson")
    assert r.solved_ci == pytest.approx((expected.low, expected.high))
    assert r.to_json()["solved_ci"] == pytest.approx([expected.low, expected.high])
    assert r.to_json()["solved_ci_method"] == "95% Wilson interval"
    assert steps_to_threshold([None] * 3, 3000).solved_ci[0] == 0.0


def test_the_median_has_a_bootstrap_interval_only_from_five_seeds():
    few = steps_to_threshold([1000, 2000, 1500, 1200], 3000)
    assert few.median_ci is None and few.to_json()["median_ci"] is None
    assert few.median_ci_method == "no interval (n = 4: too few seeds for a confidence interval, which needs 5)"
    every = steps_to_threshold([1000, 1200, 1500, 2000, 2500], 3000)  # median 1500, nothing censored
    ci = every.median_ci
    assert 1000 <= ci.low <= 1500 <= ci.high <= 2500 and ci.high > ci.low and ci.above is None
    assert f"median 1,500 steps (Kaplan–Meier), 95% bootstrap CI over 5 seeds [{ci.low:,.0f}, {ci.high:,.0f}]" \
        in every.text
    # a resample's median is one of the seeds' times: the ends are seeds' times
    assert {ci.low, ci.high} <= {1000.0, 1200.0, 1500.0, 2000.0, 2500.0}
    again = steps_to_threshold([1000, 1200, 1500, 2000, 2500], 3000)
    assert again.median_ci == ci  # a fixed seed: the same runs, the same interval


def test_a_median_censored_in_many_resamples_has_an_open_high_end():
    # 3 of 5 solved: a resample with 3 or more censored seeds has no median within the budget
    r = steps_to_threshold([1000, 2000, None, 1500, None], 3000)
    assert r.median == 2000.0 and r.median_ci.high is None and r.median_ci.above == 3000
    assert r.median_ci.low in (1000.0, 1500.0)
    assert r.text.endswith(f"95% bootstrap CI over 5 seeds [{r.median_ci.low:,.0f}, > 3,000]")
    j = r.to_json()["median_ci"]
    assert j["high"] is None and j["high_above_budget"] is True and j["above"] == 3000
    none = steps_to_threshold([None] * 5, 3000).median_ci  # nothing solved: the whole interval above the budget
    assert (none.low, none.high, none.above) == (None, None, 3000) and none.text() == "[> 3,000, > 3,000]"


def test_median_draws_resample_seeds_with_their_censoring():
    seeds = steps_to_threshold([1000, 2000, None, 1500, None], 3000).per_seed
    medians, largest = _median_draws(seeds)
    assert len(medians) == 2000 and set(largest) <= {1500.0, 2000.0, 3000.0, 1000.0}
    # every finite draw is the KM median of some multiset of these seeds: one of their times
    assert set(medians[~np.isinf(medians)]) <= {1000.0, 1500.0, 2000.0, 3000.0}
    assert 0.1 < np.isinf(medians).mean() < 0.6  # P(3+ of 5 draws censored) = 0.317 (binomial, p = 2/5)
    assert _km_median(tuple(seeds[i] for i in (2, 4, 2, 4, 0))) is None  # four censored of five: above


def test_the_ratio_has_a_bootstrap_interval_from_five_seeds_a_side():
    loop = steps_to_threshold([1000, 1200, 900, 1500, 1100], 3000)  # median 1100
    sac = steps_to_threshold([9000, 10_000, 11_000, 12_000, 14_000], 30_000)  # median 11,000
    r = steps_ratio(loop, sac)
    assert (r.ratio, r.bound) == (10.0, "exact")
    assert r.ci.low <= 10.0 <= r.ci.high and math.isfinite(r.ci.high) and r.ci.low > 0
    assert 9000 / 1500 <= r.ci.low and r.ci.high <= 14_000 / 900  # within the extreme ratios of the seeds
    assert r.text == f"= 10, 95% bootstrap CI over 5 and 5 seeds {r.ci.text()}"
    assert r.to_json()["ci"]["high_open"] is False and r.ci_method == "95% bootstrap CI over 5 and 5 seeds"
    assert steps_ratio(loop, sac).ci == r.ci  # fixed seeds


def test_a_ratio_interval_from_censored_medians():
    loop = steps_to_threshold([1000, 1200, 900, 1500, 1100], 3000)  # median 1100
    # SAC: one seed of five solved: its median is censored in nearly every resample -> open high end
    sac = steps_to_threshold([None, None, None, 25_000, None], 30_000)
    r = steps_ratio(loop, sac)
    assert r.bound == "lower" and r.ratio == pytest.approx(30_000 / 1100)
    assert math.isinf(r.ci.high) and r.ci.text().endswith(", ∞)") and r.ci.text().startswith("[")
    # its low end: the censored resamples' lower bounds (budget / the loop's median), never above them
    assert 30_000 / 1500 <= r.ci.low <= 30_000 / 900
    j = r.to_json()["ci"]
    assert j["high"] is None and j["high_open"] is True and j["low_open"] is False
    # the loop censored in most resamples: the low end is open (0), the high end finite
    slow_loop = steps_to_threshold([None, None, None, 1000, None], 3000)
    fast_sac = steps_to_threshold([5000, 6000, 7000, 8000, 9000], 30_000)
    u = steps_ratio(slow_loop, fast_sac)
    assert u.bound == "upper" and u.ci.low == 0 and u.to_json()["ci"]["low_open"] is True
    assert 0 < u.ci.high <= 9000 / 1000 and u.ratio <= u.ci.high
    assert u.ci.text() == f"(0, {u.ci.high:.3g}]"  # open below: shown as a bound, not as a measured 0
