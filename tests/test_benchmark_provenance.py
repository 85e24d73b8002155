"""benchmarks/provenance.py: a recorded benchmark names the code that ran, read when it started."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from provenance import git_state  # noqa: E402


def test_git_state_keeps_the_start_and_flags_a_tree_that_changed_during_the_run():
    now = git_state()
    assert now["commit"] and len(now["commit"]) == 40 and isinstance(now["changed_files"], list)
    same = git_state(at_start=now)
    assert same == {**now, "changed_during_run": False}
    earlier = {**now, "commit": "0" * 40}  # a commit made while the run ran
    moved = git_state(at_start=earlier)
    assert moved["commit"] == "0" * 40 and moved["changed_during_run"] is True and moved["at_end"] == now
