"""Shared fixtures: run folders made once per test session (tiny budgets, fixed seeds)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.register_assert_rewrite("helpers")

from helpers import ENV_ID, TINY_PPO, assert_ok, run_cli  # noqa: E402

# `make test-fast` (pytest -m fast), the edit loop: every cheap unit-level file, and one end-to-end
# test per workflow (robust pendulum, SAR on the MyoSuite hand, forward model + MPC on Reacher).
FAST_FILES = {
    "test_layers.py", "test_runner.py", "test_recipes.py", "test_schedules.py", "test_wrappers.py", "test_sar.py",
    "test_lqr.py", "test_pid.py", "test_dynamics_collect.py", "test_sklearn_import.py", "test_faults_success.py",
    "test_steps_to_success.py", "test_myosuite.py", "test_synergy_wrapper.py", "test_plots.py", "test_dynamics.py",
    "test_extras.py", "test_runs.py", "test_results.py",
}
FAST_TESTS = {
    "tests/test_train_evaluate.py::test_evaluate_run_folder",  # pendulum: train (CLI), evaluate, plot
    "tests/test_sar_cli.py::test_fit_by_vaf_writes_a_loadable_sar",  # SAR: play, collect, fit
    "tests/test_reacher_study.py::test_study_runs_every_step",  # Reacher: collect, fit, check, MPC
}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in FAST_FILES or item.nodeid in FAST_TESTS:
            item.add_marker(pytest.mark.fast)


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


# ---- SAR workflow (MyoSuite hand) ----------------------------------------------------

@pytest.fixture(scope="session")
def hand_play_run(tmp_path_factory) -> Path:
    """A finished tiny SAC run on the MyoSuite hand (myoHandReorient8-v0), written by the CLI."""
    from helpers import HAND_ID, TINY_HAND_SAC

    out = tmp_path_factory.mktemp("runs") / "play"
    assert_ok(run_cli("train", HAND_ID, *TINY_HAND_SAC, "--seed", "0", "--no-progress", "--out", out))
    return out


@pytest.fixture(scope="session")
def hand_activations(hand_play_run, tmp_path_factory) -> Path:
    """activations.npz collected by `motorlab synergies collect` (1 worker) from the hand play run:
    4 episodes at or above the median of 4 preview episodes."""
    from helpers import COLLECT_ARGS

    out = tmp_path_factory.mktemp("collect") / "w1"
    proc = run_cli("synergies", "collect", hand_play_run, *COLLECT_ARGS, "--workers", "1", "--out", out)
    assert_ok(proc)
    assert "kept 4 episodes" in proc.stdout
    return out / "activations.npz"


@pytest.fixture(scope="session")
def hand_sar(tmp_path_factory) -> Path:
    """The SAR published with MyoSuite for the hand (20 synergies x 39 muscles), imported to sar.npz."""
    from helpers import PUBLISHED_SAR
    from motorlab.synergy import import_sklearn

    out = tmp_path_factory.mktemp("sar") / "hand.npz"
    import_sklearn(PUBLISHED_SAR / "manipulation", trust=True, out=out)
    return out


@pytest.fixture(scope="session")
def legs_sar(tmp_path_factory) -> Path:
    """The SAR published with MyoSuite for the legs (20 synergies x 80 muscles), imported to sar.npz."""
    from helpers import PUBLISHED_SAR
    from motorlab.synergy import import_sklearn

    out = tmp_path_factory.mktemp("sar") / "legs.npz"
    import_sklearn(PUBLISHED_SAR / "locomotion", trust=True, out=out)
    return out
