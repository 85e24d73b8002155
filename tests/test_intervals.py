"""motorlab.intervals on hand-made numbers: no interval from fewer than 3 seeds, the IQM only where it
trims, scipy's Wilson interval for pooled episodes, the two-level bootstrap, P(A > B)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binomtest, trim_mean

from motorlab.intervals import across_seeds, p_better, pooled_rate, two_level_interval

pytestmark = pytest.mark.fast


def test_two_seeds_give_the_mean_and_no_interval():
    s = across_seeds([0.2, 0.2])
    assert s.statistic == "mean" and s.value == pytest.approx(0.2) and s.ci is None
    assert s.text(lambda v: f"{100 * v:.0f}%") == "mean 20% (n = 2: too few seeds for an interval)"
    assert across_seeds([3.0]).text() == "3 (one seed)"


def test_three_seeds_give_the_mean_with_a_bootstrap_interval():
    s = across_seeds([1.0, 2.0, 6.0])
    assert s.statistic == "mean" and s.value == pytest.approx(3.0)  # the IQM of 3 trims nothing
    low, high = s.ci
    assert 1.0 <= low < 3.0 < high <= 6.0
    assert "[" in s.text() and "over 3 seeds" in s.text()


def test_the_iqm_from_four_seeds_is_scipys_quartile_trimmed_mean():
    values = [1.0, 2.0, 3.0, 10.0, 11.0]
    s = across_seeds(values)
    assert s.statistic == "IQM" and s.value == pytest.approx(trim_mean(values, 0.25))
    assert s.ci[0] <= s.value <= s.ci[1] and s.ci[1] > s.ci[0]
    assert across_seeds(values).ci == s.ci  # a fixed random state: the same runs, the same interval


def test_seeds_that_agree_give_no_zero_width_interval():
    s = across_seeds([1.0, 1.0, 1.0, 1.0])
    assert s.statistic == "IQM" and s.value == 1.0 and s.ci is None
    assert s.text() == "IQM 1 (no interval: the 4 seeds agree, and a bootstrap of them has no spread)"


def test_across_seeds_refuses_nothing_and_non_finite_values():
    with pytest.raises(ValueError):
        across_seeds([])
    with pytest.raises(ValueError):
        across_seeds([1.0, float("nan"), 2.0])


def test_a_pooled_success_rate_has_scipys_wilson_interval():
    r = pooled_rate([10, 12], [50, 50])
    expected = binomtest(22, 100).proportion_ci(confidence_level=0.95, method="wilson")
    assert r.rate == pytest.approx(0.22) and r.ci == pytest.approx((expected.low, expected.high))
    assert r.ci[0] < 0.22 < r.ci[1] and r.ci[1] - r.ci[0] > 0.1  # 100 episodes: a real spread
    assert "Wilson" in r.text() and "100 episodes pooled from 2 seed(s)" in r.text()
    zero = pooled_rate([0, 0], [50, 50])  # none succeeded: still an interval of nonzero width
    assert zero.ci[0] == pytest.approx(0.0, abs=1e-12) and zero.ci[1] > 0.02
    with pytest.raises(ValueError):
        pooled_rate([6], [5])


def test_the_two_level_bootstrap_resamples_seeds_and_their_episodes():
    same_seeds = [np.full(20, 5.0)] * 3  # no spread at either level: a point
    assert two_level_interval(same_seeds) == (5.0, (5.0, 5.0))
    # seeds alike on average, episodes spread: the interval comes from the episodes
    rng = np.random.default_rng(1)
    noisy = [rng.normal(0.0, 1.0, 30) for _ in range(4)]
    point, (low, high) = two_level_interval(noisy)
    assert low < point < high and 0.2 < high - low < 2.0
    # constant episodes within each seed, seeds apart: the interval comes from the seeds
    point, (low, high) = two_level_interval([np.full(10, v) for v in (0.0, 1.0, 2.0, 3.0)])
    assert point == 1.5 and 0.0 <= low < 1.5 < high <= 3.0
    assert two_level_interval(noisy, seed=3) == two_level_interval(noisy, seed=3)
    with pytest.raises(ValueError, match="too few seeds"):
        two_level_interval([np.ones(5), np.ones(5)])


def test_p_better_has_an_interval_only_from_three_seeds_a_side():
    few = p_better([2.0, 3.0], [1.0, 1.5])
    assert few.p == 1.0 and few.ci is None and "too few" in few.text()
    apart = p_better([5.0, 6.0, 7.0], [1.0, 2.0, 3.0])  # every resample: P = 1, so no zero-width "interval"
    assert apart.p == 1.0 and apart.ci is None and "do not overlap" in apart.text()
    mixed = p_better([1.0, 3.0, 5.0, 7.0], [2.0, 4.0, 6.0, 8.0])
    assert mixed.p == pytest.approx(6 / 16) and mixed.ci[0] < mixed.p < mixed.ci[1]
    lower_better = p_better([1.0, 2.0, 3.0], [5.0, 6.0, 7.0], higher_is_better=False)
    assert lower_better.p == 1.0
