"""A controller as a run folder's policy.json, which the policy loader reads back (motorlab.policies)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab.runs import POLICY_JSON, write_json


def save_controller(run_dir: Path, controller: Any) -> None:
    """Write policy.json for a PID or LQR controller (all numbers inline)."""
    write_json(Path(run_dir) / POLICY_JSON, controller.to_dict())
