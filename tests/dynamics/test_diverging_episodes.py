"""An episode that ends on a numerical fault (a diverging simulation) gives the model none of its
transitions, not only none after the fault: the run-up before MuJoCo's (or the guard's) warning
already left the physics. A generated arm's run-ups (1e7 rad/s) set a fitted model's normalizers
and turned every plan on it to NaN (benchmarks/mbrl_bodies.py, headline body 100)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motorlab.dynamics.collection import collect_transitions, whole_episodes
from motorlab.envs import EnvConfig
from motorlab.errors import MotorlabError
from tests.helpers import USER_PACKAGES

pytestmark = pytest.mark.fast
ENV = "userpkg.runaway:Runaway-v0"
EPISODES, STEPS = 6, 12


@pytest.fixture(autouse=True)
def _importable(monkeypatch):
    monkeypatch.syspath_prepend(USER_PACKAGES)


def collect(fault_at: dict[int, int], seed: int = 50):
    cfg = EnvConfig.model_validate({"id": ENV, "kwargs": {"fault_at": {str(seed + e): k for e, k in fault_at.items()}}})
    return collect_transitions(cfg, EPISODES, workers=1, seed=seed, progress=False)


@settings(max_examples=25, deadline=None)
@given(fault_at=st.dictionaries(st.integers(0, EPISODES - 1), st.integers(1, STEPS), max_size=EPISODES - 1))
def test_a_faulted_episode_gives_no_transition_at_all(fault_at):
    data = collect(fault_at)
    # a run-up that reached no fault before the time limit is physics as far as anyone can tell: kept
    faulted = sorted(e for e, k in fault_at.items() if k + 4 <= STEPS)
    kept = sorted(set(range(EPISODES)) - set(faulted))
    assert sorted(np.unique(data.episode).tolist()) == kept
    assert data.meta["numerical_faults"] == len(faulted) == len(data.meta["fault_log"])
    assert len(data.states) == STEPS * len(kept)  # every kept episode whole, to its time limit
    assert np.isfinite(data.states).all() and np.isfinite(data.next_states).all()
    calm = [e for e in kept if e not in fault_at]
    rows = np.isin(data.episode, calm)
    assert np.abs(data.states[rows]).max() < 10  # and nothing of a faulted run-up


def test_every_episode_faulting_is_one_line_that_names_the_fix():
    with pytest.raises(MotorlabError, match="every episode .* numerical fault.*timestep"):
        collect({e: 1 for e in range(EPISODES)})


@given(st.lists(st.one_of(st.none(), st.text(min_size=1, max_size=5)), max_size=20))
def test_whole_episodes_keeps_exactly_the_unfaulted(faults):
    assert whole_episodes(faults) == [i for i, f in enumerate(faults) if f is None]


def test_the_loops_episodes_name_the_faulted_ones_and_the_loop_leaves_them_out(monkeypatch):
    """run_episodes (the loop's collection) names the episodes that faulted; mbrl's _collect keeps none
    of their transitions, though the guard left their observations finite."""
    from types import SimpleNamespace

    from motorlab.dynamics.layouts import layout_for
    from motorlab.planning import mbrl
    from motorlab.planning.mpc import PlannerFaults
    from motorlab.planning.mpc_episodes import run_episodes

    fault_at = {"7": 2, "9": 5}
    cfg = EnvConfig.model_validate({"id": ENV, "kwargs": {"fault_at": fault_at}})
    layout = layout_for(ENV, 2, "observation")
    policy = SimpleNamespace(act=lambda obs: np.zeros((len(obs), 1)), reset=lambda n: None, layout=layout,
                             faults=PlannerFaults(), task=SimpleNamespace(reward_source="test"),
                             disagreement_mean=lambda: None)
    result = run_episodes(cfg, policy, 5, 6, parallel=2, progress=False, record=True)
    assert result.faulted == (1, 3) and len(result.fault_log) == 2  # seeds 7 and 9
    assert all(np.isfinite(p.observations).all() for p in result.paths)  # the guard zeroed what was not finite
    monkeypatch.setattr(mbrl, "_planner", lambda plan, model, r, explore=0.0: policy)
    monkeypatch.setattr(mbrl, "run_episodes", lambda *a, **k: result)
    plan = SimpleNamespace(seed=0, episodes_per_round=5, collect_noise=0.0, parallel=2, env_id=ENV,
                           env={"kwargs": {"fault_at": fault_at}}, collect_steps=None)
    data, faults = mbrl._collect(plan, 1, 0, model=object(), progress=False)
    assert sorted(np.unique(data.episode).tolist()) == [0, 2, 4] and faults.episodes == 2
