"""benchmarks/learner_per_hour.py's own logic on hand-made curves: the value at a wall time, the mean
curve, the Pareto front, the ranking and a task's result with its intervals."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import learner_per_hour as lph  # noqa: E402
from learner_per_hour import Point  # noqa: E402

pytestmark = pytest.mark.fast


def curve(*points: tuple[float, float]) -> list[Point]:
    return [Point(m, int(1000 * m), s, 10 * s) for m, s in points]


def test_the_value_at_a_time_is_the_last_evaluation_at_or_before_it():
    c = curve((1, 0.1), (2, 0.4), (3, 0.3))
    assert lph.value_at(c, 0.5) is None
    assert [lph.value_at(c, t) for t in (1, 1.9, 2, 2.5, 10)] == [0.1, 0.1, 0.4, 0.4, 0.3]
    assert lph.value_at(c, 2, "ret") == 4.0
    assert lph.mean_curve([c, curve((2, 0.0))], [1, 2, 3]) == [None, 0.2, 0.15]


def test_the_front_keeps_the_points_no_other_beats_at_equal_or_less_time():
    marks = [1, 2, 3]
    means = {"fast": [0.5, 0.6, 0.6], "slow": [0.0, 0.6, 0.9], "never": [0.1, 0.2, 0.3], "late": [None, None, 0.9]}
    front = lph.pareto_front(means, marks)
    assert [(p["minutes"], p["success"], p["contender"]) for p in front] == [
        (1, 0.5, "fast"), (2, 0.6, "fast"), (2, 0.6, "slow"), (3, 0.9, "late"), (3, 0.9, "slow")]  # ties keep both


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.dictionaries(st.sampled_from("abcde"), st.lists(st.one_of(st.none(), st.integers(0, 4).map(lambda k: k / 4)),
                                                         min_size=4, max_size=4), min_size=1))
def test_the_front_is_exactly_the_undominated_points(means):
    marks = [1.0, 2.0, 3.0, 4.0]
    front = lph.pareto_front(means, marks)
    points = {(m, s, n) for n, c in means.items() for m, s in zip(marks, c) if s is not None}
    on = {(p["minutes"], p["success"], p["contender"]) for p in front}
    assert on <= points
    for m, s, n in points:  # every point off the front is beaten by one on it; none on it is beaten
        beaten = any(m2 <= m and s2 >= s and (m2 < m or s2 > s) for m2, s2, _ in points)
        assert ((m, s, n) in on) == (not beaten)
    assert [p["minutes"] for p in front] == sorted(p["minutes"] for p in front)
    # along the front, more time buys strictly more success
    distinct = sorted({(p["minutes"], p["success"]) for p in front})
    assert all(a[1] < b[1] and a[0] < b[0] for a, b in zip(distinct, distinct[1:]))


def test_ranking_by_mean_success_then_return():
    final = {"a": ([0.5, 0.5], [1.0, 1.0]), "b": ([0.4, 0.6], [2.0, 2.0]), "c": ([0.9, 0.1], [0.0, 0.0]),
             "d": ([1.0, 1.0], [-5.0, -5.0])}
    assert lph.ranking(final) == ["d", "b", "a", "c"]


def summary(success: float, steps: int, episodes: int = 20) -> dict:
    return {"eval_success_rate": success, "eval_return_mean": 10 * success, "eval_episodes": episodes,
            "timesteps": steps, "train_seconds": 600.0, "stopped_by": "minutes"}


def test_a_task_result_names_the_winner_its_lead_and_honest_intervals():
    runs = {"sar-sac": {s: {"curve": curve((5, 0.2), (10, 0.3 + 0.05 * i)), "summary": summary(0.3 + 0.05 * i, 18_000)}
                        for i, s in enumerate((100, 101, 102))},
            "sar-ppo": {s: {"curve": curve((5, 0.5), (10, 0.6)), "summary": summary(0.6, 600_000)}
                        for s in (100, 101, 102)}}
    r = lph.task_result(runs, 10.0)
    assert r["winner"] == "sar-ppo" and r["ranking"] == ["sar-ppo", "sar-sac"]
    lead = r["winner_leads"]["sar-sac"]
    assert lead["success_difference"] == pytest.approx(0.6 - 0.35)
    assert lead["p_winner_better_success"]["p"] == 1.0  # every seed ahead
    assert lead["p_winner_better_success"]["ci"] is None  # 3 seeds a side: no interval
    sac = r["contenders"]["sar-sac"]
    assert sac["success"]["ci"] is None and sac["success"]["range"] == [0.3, 0.4]  # 3 seeds: a range, not a CI
    assert sac["success_pooled"]["successes"] == round(0.3 * 20) + round(0.35 * 20) + round(0.4 * 20)
    assert sac["env_steps_per_second"] == [30.0] * 3
    assert r["on_the_front"] == ["sar-ppo"]
    assert r["marks_minutes"][-1] == 10.0 and len(r["marks_minutes"]) == lph.EVALUATIONS


def test_mistakes_are_refused_before_any_run():
    with pytest.raises(SystemExit):
        lph.parse(["screen", "--contenders", "sar-sac,nonsense"])
    with pytest.raises(SystemExit):
        lph.parse(["confirm", "--seeds", "0,100"])  # a mix of development and headline seeds
    with pytest.raises(SystemExit):
        lph.parse(["screen", "--resume"])
    assert lph.parse(["confirm"]).seeds == [100, 101, 102] and lph.parse(["screen"]).seeds == [0]
    quick = lph.parse(["screen", "--quick", "--minutes", "0.2"])
    assert quick.minutes == 0.2 and quick.episodes == lph.QUICK["episodes"]  # what is given wins over --quick's
