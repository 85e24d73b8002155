"""Shared helpers and run folders made once per test session (tiny budgets, fixed seeds)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

ENV_ID = "InvertedPendulum-v5"

# The tiny PPO budget every SB3 test uses: two rollouts of 128 steps.
TINY_PPO = ["--algo", "ppo", "--timesteps", "256", "--set", "n_steps=128", "--set", "batch_size=64"]


def run_cli(*args: str | os.PathLike, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    """`python -m motorlab ARGS` in a fresh process, as a user would run it."""
    return subprocess.run(
        [sys.executable, "-m", "motorlab", *map(str, args)],
        capture_output=True, text=True, cwd=cwd, timeout=timeout,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )


def assert_ok(proc: subprocess.CompletedProcess) -> None:
    """The command succeeded; on failure show what it printed."""
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"


def assert_one_line_error(proc: subprocess.CompletedProcess, *fragments: str) -> str:
    """Exit code 2, stderr is one line starting with 'error:', no traceback anywhere,
    and the message contains every fragment. Returns the message."""
    shown = f"exit {proc.returncode}\nstdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    assert proc.returncode == 2, shown
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout, shown
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, shown
    assert lines[0].startswith("error:"), shown
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in the message\n{shown}"
    return lines[0]


def read_summary(run_dir: Path) -> dict:
    return json.loads((Path(run_dir) / "summary.json").read_text())


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
