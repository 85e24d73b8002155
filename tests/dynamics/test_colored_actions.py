"""dynamics collect's colored random actions: within the bounds, spread over them, smoother as beta
grows, reproducible by seed, in both collection paths; bad values refused in one line."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab.dynamics.collection import collect_transitions, random_actions
from motorlab.errors import MotorlabError

# not in `make test-fast` (~20 s of generated cases): `make test` runs it


@given(beta=st.floats(0, 3), steps=st.integers(2, 300), seed=st.integers(0, 2**32 - 1),
       low=st.floats(-5, 0, exclude_max=True), width=st.floats(0.1, 10))
@settings(max_examples=60, deadline=None)
def test_colored_actions_stay_in_their_bounds_and_repeat_by_seed(beta, steps, seed, low, width):
    lo, hi = np.array([low, -1.0]), np.array([low + width, 1.0])
    a = random_actions(np.random.default_rng(seed), lo, hi, 3, steps, beta)
    assert a.shape == (3, steps, 2) and np.isfinite(a).all()
    assert (a >= lo).all() and (a <= hi).all()
    assert np.array_equal(a, random_actions(np.random.default_rng(seed), lo, hi, 3, steps, beta))


def test_redder_actions_change_less_from_step_to_step_and_still_cover_the_range():
    lo, hi = -np.ones(2), np.ones(2)
    change = {}
    for beta in (0.0, 1.0, 2.0):
        a = random_actions(np.random.default_rng(0), lo, hi, 300, 100, beta)
        change[beta] = np.abs(np.diff(a, axis=1)).mean()
        counts, _ = np.histogram(a, bins=4, range=(-1, 1))
        assert counts.min() > 0.15 * a.size  # every quarter of the range is used (uniform: 25% each)
    assert change[0.0] > change[1.0] > change[2.0]
    assert change[0.0] == pytest.approx(2 / 3, rel=0.05)  # independent uniform draws on [-1, 1]: E|x - y| = 2/3


@pytest.mark.parametrize("workers", [1, 2])
def test_both_collection_paths_take_the_color(workers):
    white = collect_transitions("Pendulum-v1", 2, workers=workers, seed=1, progress=False)
    red = collect_transitions("Pendulum-v1", 2, workers=workers, seed=1, progress=False, noise_beta=2.0)
    again = collect_transitions("Pendulum-v1", 2, workers=workers, seed=1, progress=False, noise_beta=2.0)
    assert np.array_equal(red.actions, again.actions) and not np.array_equal(white.actions, red.actions)

    def step_change(d):
        return np.abs(np.diff(d.actions[:, 0])).mean()

    assert step_change(red) < 0.5 * step_change(white)


def test_reacher_fast_path_takes_the_color():
    white = collect_transitions("Reacher-v5", 20, seed=0, workers=1, progress=False)
    red = collect_transitions("Reacher-v5", 20, seed=0, workers=1, progress=False, noise_beta=2.0)
    per_episode = red.actions.reshape(20, 50, 2)
    assert np.abs(np.diff(per_episode, axis=1)).mean() < 0.5 * np.abs(np.diff(white.actions.reshape(20, 50, 2),
                                                                              axis=1)).mean()


@pytest.mark.parametrize("beta", [-1.0, float("nan")])
def test_a_bad_color_is_refused_in_one_line(beta):
    with pytest.raises(MotorlabError, match="--noise-beta"):
        collect_transitions("Pendulum-v1", 1, workers=1, progress=False, noise_beta=beta)


def test_a_trained_policy_is_not_colored(tmp_path):
    with pytest.raises(MotorlabError, match="--noise-beta colors random actions"):
        collect_transitions("Pendulum-v1", 1, policy=str(tmp_path), workers=1, progress=False, noise_beta=1.0)
