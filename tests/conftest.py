"""Shared fixtures: run folders made once per test session (tiny budgets, fixed seeds)."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import time
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
# A test that sends Ctrl-C to a motorlab it started plays a user at a terminal. Started in the background
# of a non-interactive shell (`make test &`, nohup), this process has SIGINT ignored, which its children
# inherit, and motorlab rightly keeps an ignored signal ignored: those tests would then test the
# background's rules. Restore the terminal's (a test that wants SIGINT ignored sets it in its child).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
pytest.register_assert_rewrite("tests.helpers")

from tests.helpers import ENV_ID, TINY_PPO, assert_ok, run_cli, scaled_recipe  # noqa: E402


@pytest.fixture(autouse=True)
def no_process_outlives_its_test():
    """Whatever a test calls must not leave a child process behind (a library's pool kept for
    reuse, a worker not joined): the next test in this process would find it, and a user's
    command would end with it still running. A child gets 5 s to finish exiting."""
    yield
    deadline = time.monotonic() + 5
    while mp.active_children() and time.monotonic() < deadline:
        time.sleep(0.05)
    left = mp.active_children()
    assert not left, f"the test left child processes running: {left}"

# ---- `make test`: pytest -n 2 --dist loadfile, with two changes (pytest_xdist_make_scheduler) ----
# Each test file is one unit of work for one worker, its tests sharing their module fixtures and
# folders. 1. Files that share an expensive session fixture are one unit, so that it is made once.
SHARED = {
    # sar_hand_quick (below): its report in Chromium, and the SAR study's steps
    "tests/studies/test_bundled_reports.py": "sar-hand-quick", "tests/studies/test_sar_recipes.py": "sar-hand-quick",
    # hand_play_run and hand_activations: SAC on the MyoSuite hand, and activations collected from it
    "tests/evaluation/test_activations.py": "hand", "tests/synergies/test_steps.py": "hand", "tests/rl/test_determinism.py": "hand",
    "tests/evaluation/test_zeroshot.py": "hand",
    # one local Ray head (ray_address, below), started once for both and stopped with `ray stop --force`,
    # which stops every Ray on the machine: one unit, so never beside another Ray test
    "tests/sweeps/test_sweep.py": "ray", "tests/tuning/test_ray_search.py": "ray",
}
# ... and the tests of these files are a unit each: they share nothing, and together they would
# be the longest unit by far (each notebook runs in its own kernel)
EACH_TEST = {"tests/test_notebooks.py"}
# 2. Units start longest first (xdist would start the files with the most tests first), so the
# last to start are short and both workers finish together. About how many seconds each unit
# takes alone on an idle 2-core machine (pytest --durations); a file not listed here starts first
# (it may be long).
SECONDS = {
    "tests/rl/test_tqc.py": 5, "tests/rl/test_crossq.py": 9, "tests/rl/test_recurrent_ppo.py": 6,
    "tests/rl/test_algos.py": 3, "tests/envs/test_catalog.py": 3, "tests/test_command.py": 3,
    "ray": 100, "tests/envs/test_upkie.py": 25, "sar-hand-quick": 110, "hand": 110, "tests/planning/test_mbrl.py": 90,
    "tests/tuning/test_tune.py": 75, "tests/envs/test_user_env.py": 35, "tests/studies/test_schedule.py": 30,
    "tests/synergies/test_signals.py": 20, "tests/rl/test_train.py": 50, "tests/trackers/test_trackers.py": 30,
    "tests/adversarial/test_fuzz.py": 25, "tests/report/test_html.py": 31, "tests/rl/test_checkpoint.py": 31, "tests/test_recipes.py": 27,
    "tests/test_safe_loading.py": 24, "tests/dynamics/test_steps.py": 20, "tests/robustness_curves/test_curves.py": 17,
    "tests/rl/test_faults_success.py": 15, "tests/test_deploy_onnx.py": 15, "tests/evaluation/test_pool.py": 15,
    "tests/test_extras.py": 13, "tests/dynamics/test_train.py": 13, "tests/test_cli.py": 11,
    "tests/studies/test_reacher_recipe.py": 11, "tests/synergies/test_sklearn_export.py": 9, "tests/report/test_plots.py": 9,
    "tests/rl/test_monitor.py": 7, "tests/envs/test_myosuite.py": 5.5, "tests/synergies/test_wrapper.py": 4,
    "tests/dynamics/test_rewards.py": 1.4, "tests/controllers/test_pid.py": 1, "tests/synergies/test_sklearn_import.py": 1,
    "tests/envs/test_disturbances.py": 0.7, "tests/report/test_results.py": 0.6, "tests/test_layers.py": 0.5,
    "tests/controllers/test_lqr.py": 0.4, "tests/dynamics/test_collection.py": 0.4, "tests/rl/test_schedules.py": 0.2,
    "tests/studies/test_runner.py": 0.2, "tests/synergies/test_sar.py": 0.2, "tests/envs/test_wrappers.py": 0.2, "tests/test_runs.py": 0.05,
    "tests/test_stats.py": 1.2,
    "tests/api/test_policies.py": 60, "tests/test_docs.py": 35, "tests/test_notebooks.py": 1, "tests/studies/test_sar_legs_recipe.py": 5,
    "tests/envs/test_spaces.py": 25, "tests/envs/test_spaces_model_based.py": 30, "tests/adversarial/test_run_folders.py": 60,
    "tests/adversarial/test_spaces_and_training.py": 25, "tests/adversarial/test_model_based.py": 12,
    "tests/adversarial/test_settings_and_urls.py": 15,
    # issue 52's generated and signal tests
    "tests/adversarial/test_signals.py": 30, "tests/adversarial/test_settings_generated.py": 30,
    "tests/adversarial/test_user_code_failures.py": 25, "tests/adversarial/test_spaces_generated.py": 15,
    "tests/api/test_errors.py": 15, "tests/adversarial/test_os_errors.py": 6, "tests/test_claims.py": 4,
    "tests/adversarial/test_run_folder_lifecycle.py": 3, "tests/adversarial/test_credentials.py": 3,
    "tests/planning/test_oracle.py": 12, "tests/planning/test_planning.py": 20,
    "tests/envs/test_cartpole_swingup.py": 3, "tests/studies/test_mbrl_cartpole_recipe.py": 40,
    "tests/dynamics/test_diverging_episodes.py": 5, "tests/dynamics/test_layouts.py": 3,
    # issue 53's
    "tests/test_intervals_generated.py": 20, "tests/test_bodies.py": 20, "tests/test_mbrl_bodies.py": 11,
    "tests/dynamics/test_colored_actions.py": 18, "tests/test_docs_numbers.py": 8, "tests/test_benchmark_mbrl.py": 5,
    "tests/test_benchmark_table.py": 14, "tests/test_benchmark_provenance.py": 3, "tests/test_intervals.py": 6,
    "tests/dynamics/test_auto_epochs.py": 2,
    "tests/synergies/test_emg.py": 25,  # issue 55's
    "tests/synergies/test_analysis.py": 17, "tests/synergies/test_analysis_cli.py": 36,
    "tests/synergies/test_names_and_plot.py": 28, "tests/test_one_door.py": 12,
    "tests/synergies/test_ablation.py": 35,  # issue 55's
    # issue 54's
    "tests/rl/test_sar_presets.py": 22, "tests/rl/test_wall_budget.py": 25, "tests/test_benchmark_learner_per_hour.py": 3,
    "tests/test_gpu_check.py": 3, "tests/test_benchmark_sar_hand_scaled.py": 5, "tests/planning/test_planner_registry.py": 5,
    "tests/test_zygote.py": 9,  # issue 56's
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[sar_synergies]": 85,
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[your_own_body]": 45,
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[robust_pendulum]": 40,
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[forward_model_mpc]": 20,
}


def seconds(nodeid: str) -> float:
    """About how long the unit of this test takes (a unit of one test: else its file's figure); unknown: inf."""
    return SECONDS.get(unit(nodeid), SECONDS.get(nodeid.split("::", 1)[0], float("inf")))


# ---- `make test` and `make test-long` --------------------------------------------------------------
# make test (about 11 min on 2 cores) runs every test but these, marked `long`; make test-long runs them, and CI
# runs both. Each is an end-to-end run whose parts make test covers on their
# own, a benchmark's rehearsal, a learning comparison that needs a real budget, or a second backend's equality.
LONG = {
    "tests/sweeps/test_sweep.py::test_ray_backend_gives_the_same_folders_and_aggregate": "Ray: the same sweep on a cluster",
    "tests/tuning/test_ray_search.py::test_ray_backend_searches_on_a_cluster_and_asha_stops_a_hopeless_trial": "Ray: "
                                                                                     "the search on a cluster (ASHA)",
    "tests/tuning/test_ray_search.py::test_ray_backend_asha_starts_from_the_studys_earlier_trials": "Ray: ASHA resumed",
    "tests/test_gpu_check.py::test_a_cpu_rehearsal_runs_every_part_and_records_its_rates": "a benchmark's rehearsal",
    "tests/envs/test_upkie.py::test_upkie_recipe_runs_end_to_end_on_tiny_budgets": "a recipe end to end (Upkie's env, "
                                                                                     "PID and video are tested alone)",
    "tests/envs/test_upkie.py::test_video_of_a_pid_episode": "a video of Upkie (videos are tested on MuJoCo)",
    "tests/envs/test_spaces.py::test_her_beats_plain_sac_on_the_sparse_maze": "a learning comparison",
    "tests/envs/test_spaces.py::test_a_her_run_killed_resumes_with_its_replay_buffer": "HER's resume (SAC's is tested)",
    "tests/studies/test_schedule.py::test_parallel_study_equals_the_sequential_one": "a study run twice (an interrupted "
                                                                                      "parallel study is tested)",
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[sar_synergies]": "a notebook end to end",
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[your_own_body]": "a notebook end to end",
    "tests/test_notebooks.py::test_notebook_runs_on_tiny_budgets[robust_pendulum]": "a notebook end to end",
    "tests/synergies/test_signals.py::test_robot_quick_recipe_end_to_end": "a recipe end to end",
    "tests/studies/test_sar_legs_recipe.py::test_sar_legs_quick_end_to_end": "a recipe end to end",
    "tests/studies/test_sar_legs_recipe.py::test_published_locomotion_sar_recipe_runs": "a recipe end to end",
    "tests/sweeps/test_sweep.py::test_recipe_sweep_runs_whole_studies_with_the_setting_applied": "whole studies per trial",
    "tests/adversarial/test_signals.py::test_sighup_stops_a_study_that_resume_then_finishes": "a whole study stopped "
                                                                                               "(SIGHUP of a train is tested)",
    "tests/adversarial/test_signals.py::test_sigterm_stops_a_sweep_that_resume_then_finishes": "a whole sweep stopped",
    "tests/envs/test_user_env.py::test_synergies_of_the_arms_motor_commands_and_sar_training": "a workflow end to end",
    "tests/envs/test_user_env.py::test_recipe_with_imports": "a recipe end to end",
    "tests/envs/test_user_env.py::test_sweep_of_a_users_env": "a sweep end to end",
    "tests/tuning/test_tune.py::test_a_recipe_is_tuned_by_its_step_fields_and_the_best_runs_as_a_recipe": "whole studies "
                                                                                                          "per trial",
    "tests/rl/test_sar_presets.py::test_off_policy_contenders_train_at_their_ratio_and_evaluate[sar-crossq-1]": "the "
                                                                                                  "slowest contender",
    "tests/studies/test_mbrl_cartpole_recipe.py::test_scaled_study_compares_evaluation_curves": "a recipe end to end "
                                    "(the loop and the Reacher recipe are tested; test-fast runs it as its workflow's)",
    "tests/rl/test_tqc.py::test_tunes": "a search per algorithm (tune is tested on its own)",
    "tests/rl/test_crossq.py::test_tunes": "a search per algorithm (tune is tested on its own)",
    "tests/rl/test_recurrent_ppo.py::test_tunes": "a search per algorithm (tune is tested on its own)",
    "tests/trackers/test_trackers.py::test_a_sweep_targets_own_track_tracks_its_trials": "a whole sweep, tracked "
                                                                                          "(applying --track is tested)",
    "tests/trackers/test_trackers.py::test_a_tune_targets_own_track_tracks_its_trials": "a whole search, tracked "
                                                                                         "(applying --track is tested)",
    "tests/sweeps/test_sweep.py::test_interrupted_training_trial_resumes_from_its_checkpoint": "a sweep's trial resumed "
                                                                                "(a recipe's and a run's are tested)",
    "tests/adversarial/test_spaces_and_training.py::test_resume_of_a_discrete_run_after_ctrl_c": "a discrete run "
                                                                                   "resumed (killed and resumed: tested)",
    "tests/synergies/test_names_and_plot.py::test_plot_draws_a_vaf_runs_band[None]": "the band in-sample (with "
                                                                                       "--cv: tested)",
}


def is_long(nodeid: str) -> bool:
    return any(nodeid == key or nodeid.startswith(key + "::") or nodeid.startswith(key + "[") for key in LONG)


def pytest_collection_modifyitems(config, items):
    for item in items:
        if is_long(item.nodeid):
            item.add_marker(pytest.mark.long)
    files = {item.nodeid.split("::", 1)[0] for item in items}
    stale = [key for key in LONG if key.split("::", 1)[0] in files and not any(is_long(i.nodeid) for i in items
                                                                                  if i.nodeid.startswith(key))]
    if stale and not config.getoption("keyword") and not config.getoption("markexpr"):
        raise pytest.UsageError(f"tests/conftest.py LONG names tests that do not exist: {stale}")
    if hasattr(config, "workerinput"):  # an xdist worker: the units of work in the order they are handed out
        items.sort(key=lambda item: -seconds(item.nodeid))  # stable: tests keep their order


def unit(nodeid: str) -> str:
    """The unit of work a test belongs to: its file, or the name of the files it shares a fixture with."""
    path = nodeid.split("::", 1)[0]
    return nodeid if path in EACH_TEST else SHARED.get(path, path)


def pytest_xdist_make_scheduler(config, log):
    if config.getoption("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Units(LoadScopeScheduling):
        """--dist loadfile, with the units above."""

        def _split_scope(self, nodeid: str) -> str:
            return unit(nodeid)

    config.option.loadscopereorder = False  # hand the units out in collection order (sorted above)
    return Units(config, log)


# ---- one local Ray head for the "ray" unit --------------------------------------------

_ray_head: dict[str, int] = {}  # the port of the running head, while there is one


@pytest.fixture
def ray_address() -> str:
    """HOST:PORT of a local Ray head (2 CPUs; helpers.ray_head), as `ray start --head` prints it. The
    tests of one unit of work share it (starting a head takes seconds); it is stopped with
    `ray stop --force` when the next test belongs to another unit, or none follows."""
    from tests.helpers import free_port, ray_head

    if "port" not in _ray_head:
        port = free_port()
        ray_head(port)
        _ray_head["port"] = port
    return f"127.0.0.1:{_ray_head['port']}"


def pytest_runtest_teardown(item, nextitem):
    if "port" in _ray_head and (nextitem is None or unit(nextitem.nodeid) != unit(item.nodeid)):
        from tests.helpers import ray_stop

        del _ray_head["port"]
        ray_stop()


def pytest_sessionfinish(session):
    if "port" in _ray_head:  # a run stopped early (-x, Ctrl-C) leaves no Ray behind
        from tests.helpers import ray_stop

        del _ray_head["port"]
        ray_stop()


@pytest.fixture(scope="module", autouse=True)
def user_modules_stay_in_their_file():
    """A test file that imports a user's env module in this process (motorlab then passes it on to
    every process it starts, in $MOTORLAB_IMPORTS) does not pass it on to later files' processes,
    which may not find it (tests/userpkg is on their PYTHONPATH only where a test puts it)."""
    before = os.environ.get("MOTORLAB_IMPORTS")
    yield
    if before is None:
        os.environ.pop("MOTORLAB_IMPORTS", None)
    else:
        os.environ["MOTORLAB_IMPORTS"] = before


@pytest.fixture(scope="session")
def ppo_run(tmp_path_factory) -> Path:
    """A finished tiny PPO run folder, written by the CLI."""
    out = tmp_path_factory.mktemp("runs") / "ppo"
    assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--seed", "0", "--no-progress", "--out", out, user_modules=False))
    return out


@pytest.fixture(scope="session")
def fast_run(tmp_path_factory) -> Path:
    """A finished run of the `fast` preset (linear model + LQR), stopped once solved."""
    out = tmp_path_factory.mktemp("runs") / "fast"
    assert_ok(run_cli("train", ENV_ID, "--preset", "fast", "--until-solved", "--timesteps", "3000",
                      "--no-progress", "--out", out, user_modules=False))
    return out


# ---- SAR workflow (MyoSuite hand) ----------------------------------------------------

@pytest.fixture(scope="session")
def hand_play_run(tmp_path_factory) -> Path:
    """A finished tiny SAC run on the MyoSuite hand (myoHandReorient8-v0), written by the CLI."""
    from tests.helpers import HAND_ID, TINY_HAND_SAC

    out = tmp_path_factory.mktemp("runs") / "play"
    assert_ok(run_cli("train", HAND_ID, *TINY_HAND_SAC, "--seed", "0", "--no-progress", "--out", out,
                      user_modules=False))
    return out


@pytest.fixture(scope="session")
def hand_activations(hand_play_run, tmp_path_factory) -> Path:
    """activations.npz collected by `motorlab synergies collect` (1 worker) from the hand play run:
    4 episodes at or above the median of 4 preview episodes."""
    from tests.helpers import COLLECT_ARGS

    out = tmp_path_factory.mktemp("collect") / "w1"
    proc = run_cli("synergies", "collect", hand_play_run, *COLLECT_ARGS, "--workers", "1", "--out", out,
                   user_modules=False)
    assert_ok(proc)
    assert "kept 4 episodes" in proc.stdout
    return out / "activations.npz"


@pytest.fixture(scope="session")
def hand_sar(tmp_path_factory) -> Path:
    """The SAR published with MyoSuite for the hand (20 synergies x 39 muscles), imported to sar.npz."""
    from motorlab.api.synergies import import_sklearn
    from tests.helpers import PUBLISHED_SAR

    out = tmp_path_factory.mktemp("sar") / "hand.npz"
    import_sklearn(PUBLISHED_SAR / "manipulation", trust=True, out=out)
    return out


@pytest.fixture(scope="session")
def legs_sar(tmp_path_factory) -> Path:
    """The SAR published with MyoSuite for the legs (20 synergies x 80 muscles), imported to sar.npz."""
    from motorlab.api.synergies import import_sklearn
    from tests.helpers import PUBLISHED_SAR

    out = tmp_path_factory.mktemp("sar") / "legs.npz"
    import_sklearn(PUBLISHED_SAR / "locomotion", trust=True, out=out)
    return out


@pytest.fixture(scope="session")
def sar_hand_quick(tmp_path_factory) -> tuple[Path, Path]:
    """The bundled sar-hand-quick study at the tests' scale (helpers.SCALED), run once from the CLI:
    (its recipe file, its folder). Its report is opened in Chromium (test_bundled_reports.py) and its
    steps are checked (test_sar_study.py); both files are one unit of `make test` (SHARED)."""
    folder = tmp_path_factory.mktemp("sar-hand-quick")
    recipe = scaled_recipe("sar-hand-quick", folder)
    assert_ok(run_cli("run", recipe, "--out", folder / "study", timeout=900, user_modules=False))
    return recipe, folder / "study"
