"""motorlab.intervals on hand-made numbers: the seeds' range (not a CI) from 2-4 seeds, a bootstrap CI
from 5, the IQM only where it trims, scipy's Wilson interval for k of n, P(A > B) with its ties and
its seeds that do not overlap."""

from __future__ import annotations

import pytest
from scipy.stats import binomtest, trim_mean

from motorlab.intervals import MIN_SEEDS_FOR_INTERVAL, across_seeds, p_better, pooled_rate, wilson

pytestmark = pytest.mark.fast


def test_one_seed_has_no_interval():
    s = across_seeds([3.0])
    assert s.text() == "3 (one seed)" and s.ci is None and s.range is None and s.interval is None


def test_three_seeds_give_their_range_named_as_such_and_no_ci():
    s = across_seeds([1.0, 2.0, 6.0])
    assert s.statistic == "mean" and s.value == pytest.approx(3.0)  # the IQM of 3 trims nothing
    assert s.ci is None and s.range == (1.0, 6.0) and s.interval == (1.0, 6.0)
    assert s.text() == "mean 3 [1, 6] (range of 3 seeds, not a confidence interval: one needs 5 seeds)"
    assert "95%" not in s.text() and "CI over" not in s.text()
    assert s.to_json()["ci"] is None and s.to_json()["range"] == [1.0, 6.0]


def test_two_and_four_seeds_give_their_range_too():
    two = across_seeds([0.1, 0.3])
    assert two.ci is None and two.text(lambda v: f"{100 * v:.0f}%").startswith("mean 20% [10%, 30%] (range of 2 seeds")
    four = across_seeds([1.0, 2.0, 3.0, 10.0])
    assert four.statistic == "IQM" and four.ci is None and four.interval == (1.0, 10.0)
    assert "range of 4 seeds" in four.text() and "95%" not in four.text()


def test_five_seeds_give_a_bootstrap_ci_of_the_iqm():
    assert MIN_SEEDS_FOR_INTERVAL == 5
    values = [1.0, 2.0, 3.0, 10.0, 11.0]
    s = across_seeds(values)
    assert s.statistic == "IQM" and s.value == pytest.approx(trim_mean(values, 0.25))
    assert s.ci[0] <= s.value <= s.ci[1] and s.ci[1] > s.ci[0] and s.interval == s.ci
    assert s.range == (1.0, 11.0)  # kept in the JSON, not shown
    assert "(95% stratified-bootstrap CI over 5 seeds)" in s.text() and "range" not in s.text()
    assert across_seeds(values).ci == s.ci  # a fixed random state: the same runs, the same interval


def test_seeds_that_agree_show_no_point_as_an_interval():
    few = across_seeds([1.0, 1.0, 1.0, 1.0])
    assert few.value == 1.0 and few.ci is None and few.interval is None
    assert few.text() == "IQM 1 (the 4 seeds agree; no confidence interval below 5 seeds)"
    many = across_seeds([1.0] * 5)
    assert many.ci is None and many.interval is None and "[" not in many.text()
    assert many.text() == "IQM 1 (no interval: the 5 seeds agree, and a bootstrap of them has no spread)"


def test_across_seeds_refuses_nothing_and_non_finite_values():
    with pytest.raises(ValueError):
        across_seeds([])
    with pytest.raises(ValueError):
        across_seeds([1.0, float("nan"), 2.0])


def test_wilson_is_scipys_wilson_interval():
    for k, n in ((0, 5), (3, 5), (5, 5), (22, 100)):
        expected = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
        assert wilson(k, n) == pytest.approx((max(0.0, expected.low), min(1.0, expected.high)))
    assert wilson(0, 5)[0] == 0.0 and wilson(5, 5)[1] == 1.0  # clipped to [0, 1], never a float past them
    with pytest.raises(ValueError):
        wilson(6, 5)


def test_a_pooled_success_rate_has_the_wilson_interval():
    r = pooled_rate([10, 12], [50, 50])
    assert r.rate == pytest.approx(0.22) and r.ci == pytest.approx(wilson(22, 100))
    assert r.ci[0] < 0.22 < r.ci[1] and r.ci[1] - r.ci[0] > 0.1  # 100 episodes: a real spread
    assert "Wilson" in r.text() and "100 episodes pooled from 2 seed(s)" in r.text()
    zero = pooled_rate([0, 0], [50, 50])  # none succeeded: still an interval of nonzero width
    assert zero.ci[0] == 0.0 and zero.ci[1] > 0.02
    with pytest.raises(ValueError):
        pooled_rate([6], [5])


def test_p_better_has_an_interval_only_from_five_seeds_a_side():
    few = p_better([2.0, 3.0, 4.0], [1.0, 1.5, 3.0])
    assert few.ci is None and "too few" in few.text() and "n = 3 and 3 seeds" in few.text()
    mixed = p_better([1.0, 3.0, 5.0, 7.0, 9.0], [2.0, 4.0, 6.0, 8.0, 10.0])
    assert mixed.p == pytest.approx(10 / 25) and mixed.ci[0] < mixed.p < mixed.ci[1]
    assert "95% stratified-bootstrap CI over 5 and 5 seeds" in mixed.text() and mixed.overlap == "mixed"
    assert p_better([1.0, 2.0, 3.0], [5.0, 6.0, 7.0], higher_is_better=False).p == 1.0


def test_all_tied_seeds_say_so_and_never_that_they_do_not_overlap():
    # sar_legs' ten seeds, all at 0 success: P is one half, and the seeds are tied, not apart
    tied = p_better([0.0] * 5, [0.0] * 5)
    assert (tied.p, tied.ci, tied.overlap) == (0.5, None, "tied")
    assert tied.method == "all tied: every seed of both sides has the same value"
    assert "overlap" not in tied.text() and tied.to_json()["method"] == tied.method
    assert p_better([1.0, 1.0], [1.0, 1.0, 1.0]).method.startswith("all tied")  # with few seeds too


def test_do_not_overlap_only_when_every_a_is_above_or_below_every_b():
    apart = p_better([5.0, 6.0, 7.0, 8.0, 9.0], [1.0, 2.0, 3.0, 4.0, 4.5])
    assert (apart.p, apart.ci, apart.overlap) == (1.0, None, "apart") and "do not overlap" in apart.text()
    below = p_better([1.0] * 5, [2.0] * 5)
    assert (below.p, below.overlap) == (0.0, "apart") and "do not overlap" in below.text()
    touching = p_better([5.0, 6.0, 7.0, 8.0, 9.0], [1.0, 2.0, 3.0, 4.0, 5.0])  # one tie at 5: they overlap
    assert touching.overlap == "mixed" and "do not overlap" not in touching.text()
    partly_tied = p_better([0.0, 0.0, 0.0, 0.0, 1.0], [0.0] * 5)
    assert partly_tied.overlap == "mixed" and partly_tied.p == pytest.approx(0.6)
    assert "tied" not in partly_tied.method and "do not overlap" not in partly_tied.method
