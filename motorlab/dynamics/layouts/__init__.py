"""The state layouts `--state NAME` knows: one module each in this package (`LAYOUT`, a `LayoutSpec`;
the module's docstring, `--state NAME`: what it is, is its line in --help), found by name as
`algos` finds algorithms. A new layout is one file.

`layout_for` and `env_layout` build an env's layout by name ("auto": the env's catalogue entry's
`state_layout`, else the observation)."""

from motorlab.dynamics.layouts._registry import (
    DEFAULT,
    LAYOUTS,
    about,
    check_name,
    env_layout,
    layout_for,
    names,
    reached_of,
    reaching,
    spec,
)

__all__ = ["DEFAULT", "LAYOUTS", "about", "check_name", "env_layout", "layout_for", "names", "reached_of", "reaching", "spec"]
