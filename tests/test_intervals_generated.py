"""Properties of motorlab.intervals and motorlab.stats' intervals on generated per-seed values
(Hypothesis): what each interval must hold whatever the seeds are."""

from __future__ import annotations

import math
from unittest.mock import patch

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab import intervals
from motorlab.intervals import MIN_SEEDS_FOR_INTERVAL, across_seeds, p_better, wilson
from motorlab.stats import steps_ratio, steps_to_threshold

# not in `make test-fast` (~20 s of generated cases): `make test` runs it

FEW = settings(max_examples=50, deadline=None, derandomize=True, database=None)
SLOW = settings(max_examples=50, deadline=None, derandomize=True, database=None)  # bootstraps of KM medians

# per-seed values with ties likely (small integers) as well as arbitrary floats
value = st.one_of(st.integers(0, 5).map(float), st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False))
BUDGET = 3000
# a seed's steps to the threshold: None (never) or a hit within the budget, from a coarse grid (ties)
hit = st.one_of(st.none(), st.integers(1, 30).map(lambda k: 100 * k))


@FEW
@given(st.lists(value, min_size=2, max_size=MIN_SEEDS_FOR_INTERVAL - 1))
def test_below_five_seeds_the_range_is_shown_and_holds_every_seed(values):
    s = across_seeds(values)
    low, high = s.range
    assert all(low <= v <= high for v in values) and low in values and high in values
    assert s.ci is None and "95%" not in s.text()
    assert s.interval == (s.range if high > low else None)
    assert ("range of" in s.method) == (high > low)


# rliable's bootstrap of 2000 resamples takes ~0.3 s a call (P(A > B)'s ~1 s); these properties hold
# for any number of resamples, so the generated tests draw fewer (REPS) and try more seeds
FEWER_RESAMPLES = 200


@FEW
@given(st.lists(value, min_size=MIN_SEEDS_FOR_INTERVAL, max_size=8))
def test_from_five_seeds_a_bootstrap_ci_lies_within_the_seeds(values):
    with patch.object(intervals, "REPS", FEWER_RESAMPLES):
        s = across_seeds(values)
    low, high = s.range
    assert all(low <= v <= high for v in values)
    tol = 1e-9 * (1 + max(abs(v) for v in values))  # a mean of floats may stray by a rounding error
    if s.ci is not None:
        assert low - tol <= s.ci[0] < s.ci[1] <= high + tol and s.interval == s.ci
        assert s.method == f"95% stratified-bootstrap CI over {len(values)} seeds"
    else:  # no width: every resample gave the same value, which only equal seeds do
        assert low == high and "agree" in s.method


@FEW
@given(st.integers(1, 200).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n))))
def test_wilson_lies_in_zero_one_and_holds_k_over_n(kn):
    k, n = kn
    low, high = wilson(k, n)
    assert 0.0 <= low <= k / n <= high <= 1.0 and high > low


@FEW
@given(st.lists(value, min_size=1, max_size=MIN_SEEDS_FOR_INTERVAL - 1),
       st.lists(value, min_size=1, max_size=MIN_SEEDS_FOR_INTERVAL + 2))
def test_p_better_is_a_probability_and_the_two_ways_sum_to_one(a, b):
    ab, ba = p_better(a, b), p_better(b, a)  # one side under 5 seeds: no bootstrap, so many examples
    assert 0.0 <= ab.p <= 1.0 and ab.p + ba.p == pytest.approx(1.0)
    tied = len(set(a) | set(b)) == 1
    assert ab.method.startswith("all tied") == tied and (ab.p == 0.5 or not tied)
    assert ab.ci is None and "too few" in ab.method or tied


small = st.integers(0, 3).map(float)  # ties, overlap and seeds apart all likely


@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(st.lists(small, min_size=MIN_SEEDS_FOR_INTERVAL, max_size=6), st.lists(small, min_size=MIN_SEEDS_FOR_INTERVAL,
                                                                              max_size=6))
def test_p_better_says_do_not_overlap_only_when_they_do_not(a, b):
    with patch.object(intervals, "REPS", FEWER_RESAMPLES):
        ab = p_better(a, b)
    apart, tied = min(a) > max(b) or max(a) < min(b), len(set(a) | set(b)) == 1
    assert ("do not overlap" in ab.method) == apart and ab.method.startswith("all tied") == tied
    if ab.ci is not None:
        assert 0.0 <= ab.ci[0] <= ab.p <= ab.ci[1] <= 1.0 and not apart and not tied


@SLOW
@given(st.lists(hit, min_size=MIN_SEEDS_FOR_INTERVAL, max_size=7))
def test_the_km_median_ci_holds_the_median_when_it_exists(steps):
    r = steps_to_threshold(steps, BUDGET)
    ci = r.median_ci
    low = math.inf if ci.low is None else ci.low
    high = math.inf if ci.high is None else ci.high
    assert low <= high
    if r.median is not None:
        assert low <= r.median <= high
    else:  # censored: the interval's top is censored too (the point is one of the resamples' values)
        assert ci.high is None and ci.above == BUDGET


@SLOW
@given(st.lists(hit, min_size=MIN_SEEDS_FOR_INTERVAL, max_size=6),
       st.lists(hit, min_size=MIN_SEEDS_FOR_INTERVAL, max_size=6))
def test_the_ratio_interval_holds_the_ratio_where_it_is_exact(a_steps, b_steps):
    a, b = steps_to_threshold(a_steps, BUDGET), steps_to_threshold(b_steps, 10 * BUDGET)
    r = steps_ratio(a, b)
    assert 0.0 <= r.ci.low <= r.ci.high
    if r.bound == "exact":
        assert r.ci.low <= r.ratio <= r.ci.high
    if r.bound == "lower":  # the ratio is only known to be above r.ratio: the interval reaches above it
        assert r.ci.high >= r.ratio
    if r.bound == "upper":
        assert r.ci.low <= r.ratio
