"""Shared fixtures: run folders made once per test session (tiny budgets, fixed seeds)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.register_assert_rewrite("helpers")

from helpers import ENV_ID, TINY_PPO, assert_ok, run_cli  # noqa: E402


@pytest.fixture(scope="session")
def ppo_run(tmp_path_factory) -> Path:
    """A finished tiny PPO run folder, written by the CLI."""
    out = tmp_path_factory.mktemp("runs") / "ppo"
    assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--seed", "0", "--no-progress", "--out", out))
    return out


@pytest.fixture(scope="session")
def fast_run(tmp_path_factory) -> Path:
    """A finished run of the `fast` preset (linear model + LQR), stopped once solved."""
    out = tmp_path_factory.mktemp("runs") / "fast"
    assert_ok(run_cli("train", ENV_ID, "--preset", "fast", "--until-solved", "--timesteps", "3000",
                      "--no-progress", "--out", out))
    return out
