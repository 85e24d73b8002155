"""The planners `--optimizer` names: one module each in this package (`PLANNER`, its class; the module's
docstring, `--optimizer NAME`: what it does, is its line in --help), found here by name as `algos` finds
algorithms. A new planner is one file.

A planner class takes (score, low, high, **settings) and says which of the plan's settings it takes
(`SETTINGS`); `plan(states, goals)` returns each env's first action."""

from motorlab.planning.planners._registry import (
    PLANNERS,
    about,
    make_planner,
    names,
    planner_class,
    settings_of,
)

__all__ = ["PLANNERS", "about", "make_planner", "names", "planner_class", "settings_of"]
