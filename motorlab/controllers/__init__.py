"""Feedback controllers: PID (pid.py) and a least-squares linear model with LQR (lqr.py).

Built-in policies without a network, below the policy loader (motorlab.policies), which loads them
by name (`pid`) or from a run folder's policy.json, and below the algorithm registry
(motorlab.algos), whose LQR learner fits them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab.runs import POLICY_JSON, write_json


def save_controller(run_dir: Path, controller: Any) -> None:
    """Write policy.json for a PID or LQR controller (all numbers inline)."""
    write_json(Path(run_dir) / POLICY_JSON, controller.to_dict())
