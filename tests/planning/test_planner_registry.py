"""Planners are a registry: a new optimizer is one file in motorlab/planning/planners/, found by name; the
settings model, --help and the plan it is given follow from it."""

from __future__ import annotations

import pytest

from motorlab.errors import MotorlabError
from motorlab.planning import planners

pytestmark = pytest.mark.fast

NEW_PLANNER = '''"""`--optimizer shooting`: random shooting, the best of `population` sampled sequences."""

import torch


class RandomShooting:
    def __init__(self, score, low, high, horizon=15, population=100, seed=0, **_):
        self.low, self.high = torch.as_tensor(low), torch.as_tensor(high)
        self.horizon, self.population = horizon, population

    def plan(self, states, goals):
        return self.low.expand(states.shape[0], -1)


SETTINGS = ("horizon", "population")
PLANNER = RandomShooting
'''


@pytest.fixture
def shooting(tmp_path, monkeypatch):
    """A user's planner file beside the bundled ones (the package's path extended, as a new file would be)."""
    (tmp_path / "shooting.py").write_text(NEW_PLANNER)
    monkeypatch.setattr(planners, "__path__", [*planners.__path__, str(tmp_path)])
    planners.names.cache_clear()
    yield
    planners.names.cache_clear()


def test_the_bundled_planners_are_their_modules():
    assert planners.names() == ("cem", "evotorch", "mppi")
    assert planners.settings_of("mppi") == ("horizon", "population", "iterations", "temperature", "noise_beta")
    assert "cem: the cross-entropy method" in planners.about()


def test_a_new_planner_is_one_file(shooting):
    from motorlab.kinds.planning import PlannerSettings

    assert "shooting" in planners.names() and "shooting: random shooting" in planners.about()
    settings = PlannerSettings.model_validate({"optimizer": "shooting", "horizon": 7, "population": 9})
    assert settings.plan() == {"horizon": 7, "population": 9}  # only what the planner takes
    planner = planners.make_planner("shooting", None, [-1.0, -2.0], [1.0, 2.0], **settings.plan())
    assert planner.horizon == 7 and planner.plan(__import__("torch").zeros(3, 4), None).shape == (3, 2)


def test_an_unknown_planner_is_one_line_with_close_matches():
    with pytest.raises(MotorlabError, match=r"--optimizer 'cme': choose cem, evotorch, mppi.*did you mean"):
        planners.make_planner("cme", None, [0.0], [1.0])
