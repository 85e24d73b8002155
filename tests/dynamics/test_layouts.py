"""State layouts are a registry: one file each in motorlab.dynamics.layouts, found by name; what a layout
reaches for its goal with (Reacher's fingertip, a Dict goal's achieved_goal) is the layout's, not the kinds'."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from motorlab.dynamics import layouts
from motorlab.dynamics.layouts import check_name, layout_for, reached_of, reaching
from motorlab.dynamics.layouts.observation import build as observation_layout
from motorlab.dynamics.state import KeySlice
from motorlab.errors import MotorlabError
from motorlab.kinds.dynamics import DynamicsCollectSettings
from motorlab.kinds.planning import MbrlSettings

NEW_LAYOUT = '''"""`--state mirror`: the observation backwards (a test's layout)."""
from motorlab.dynamics.layouts.base import LayoutSpec
from motorlab.dynamics.state import Reached, StateLayout


def build(env_id, obs_dim, keys):
    return StateLayout("mirror", tuple(f"m[{i}]" for i in range(obs_dim)), (), lambda obs: obs[..., ::-1],
                       reaching=Reached((0,), "mirrored", "mirrored entry"))


LAYOUT = LayoutSpec(build, reaching=Reached((0,), "mirrored", "mirrored entry"))
'''


@pytest.fixture
def extra_layout(tmp_path, monkeypatch):
    """A layout added as one file, where the registry looks (the package's path)."""
    (tmp_path / "mirror.py").write_text(NEW_LAYOUT)
    monkeypatch.setattr(layouts, "__path__", [*layouts.__path__, str(tmp_path)])
    layouts.names.cache_clear()
    yield "mirror"
    layouts.names.cache_clear()


def test_the_bundled_layouts_are_found_by_name_and_the_default_first():
    assert layouts.names()[0] == "observation" and "reacher" in layouts.names()
    assert "observation:" in layouts.about() and "reacher:" in layouts.about()


def test_a_new_layout_is_one_file(extra_layout):
    assert extra_layout in layouts.names()
    layout = layout_for("Pendulum-v1", 3, extra_layout)
    assert layout.state(np.array([1.0, 2.0, 3.0])).tolist() == [3.0, 2.0, 1.0]
    # the settings every kind shares take it, and its --help names it, with no other edit
    assert DynamicsCollectSettings(env="Pendulum-v1", state=extra_layout).state == extra_layout
    assert "mirror:" in layouts.about()
    assert reaching("mirrored").label == "mirrored entry"


def test_an_unknown_layout_is_one_line_with_the_choices():
    with pytest.raises(MotorlabError, match=r"unknown state layout 'reachr'; choose auto, observation, reacher.*"
                                            r"did you mean reacher"):
        check_name("reachr")
    with pytest.raises(MotorlabError, match="unknown state layout"):
        MbrlSettings(env="Pendulum-v1", state="reachr")


def test_reacher_reaches_with_its_fingertip_in_metres():
    reached = layout_for("Reacher-v5", 10).reached
    assert reached.columns == (6, 7) and reached.key == "tip" and reached.scale == (1000.0, "mm")
    assert reached_of("reacher", [], []) == reached  # a saved model's layout name is enough


def test_a_state_without_a_goal_reaches_with_nothing():
    assert layout_for("Pendulum-v1", 3).reached is None
    assert reached_of("observation", ["obs[0]", "obs[1]"], []) is None


@given(sizes=st.lists(st.integers(1, 4), min_size=1, max_size=4), achieved=st.integers(0, 4),
       desired=st.integers(0, 4), order=st.permutations(["observation", "achieved_goal", "desired_goal"]))
def test_a_dict_goal_reaches_with_its_achieved_goal_where_the_sizes_match(sizes, achieved, desired, order):
    """Generated Dict observations: the reached columns are the achieved_goal's exactly when it and the
    desired_goal are both there and the same size, and the saved labels give the same answer."""
    size = {"observation": sizes[0], "achieved_goal": achieved, "desired_goal": desired}
    keys, start = [], 0
    for key in order:
        if size[key]:
            keys.append(KeySlice(key, start, start + size[key], (size[key],)))
            start += size[key]
    layout = observation_layout("Goal-v0", start, tuple(keys))
    span = next((range(k.start, k.stop) for k in keys if k.key == "achieved_goal"), None)
    expected = tuple(span) if span is not None and desired and achieved == desired else None
    got = layout.reached
    assert (got.columns if got else None) == expected
    again = reached_of("observation", layout.labels, layout.goal_labels)
    assert (again.columns if again else None) == expected
