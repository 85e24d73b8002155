"""Every user mistake gives exit code 2 and one line 'error: ...' naming the thing and
the fix, never a traceback, and never a run folder that looks finished.

The mistakes run through `motorlab.cli.main` in this process (helpers.run_here: the same output,
exit status and files as `python -m motorlab`, without an interpreter start each); the last test
runs a real process, and other files' error tests do too."""

from __future__ import annotations

import shutil
import textwrap

import pytest

from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_cli, run_here

# ---- train -------------------------------------------------------------------------

TRAIN_ERRORS = [
    (["InvertedPendulm-v5"], ["InvertedPendulm-v5", "InvertedPendulum-v5"]),  # close match suggested
    ([ENV_ID, "--delay", "0.01"], ["0.01", "0.04"]),  # tau below the env's dt (alpha > 1)
    ([ENV_ID, "--delay", "-1"], ["delay", "-1"]),
    ([ENV_ID, "--delay", "0.2", "--delay-on", "sensor"], ["delay-on"]),
    ([ENV_ID, "--timesteps", "-5"], ["--timesteps"]),
    ([ENV_ID, "--history", "0"], ["--history"]),
    ([ENV_ID, "--algo", "ppx"], ["--algo"]),
    ([ENV_ID, "--preset", "fats"], ["fats", "fast"]),
    ([ENV_ID, "--reward", "quadratik"], ["quadratik", "quadratic"]),
    ([ENV_ID, "--lr", "fast"], ["learning-rate", "fast"]),
    ([ENV_ID, "--clip-range", "linear:0.3"], ["clip-range"]),
    ([ENV_ID, "--set", "n_steps"], ["n_steps", "KEY=VALUE"]),
    (["Pendulum-v1", "--until-solved", "--timesteps", "100"], ["Pendulum-v1", "--solve-return"]),
    ([ENV_ID, "--algo", "sac", "--clip-range", "0.2", "--timesteps", "100"], ["PPO"]),
    ([ENV_ID, "--algo", "ppo", "--timesteps", "100", "--set", "n_stepz=64"], ["n_stepz"]),
]


@pytest.mark.parametrize("args, fragments", TRAIN_ERRORS, ids=[" ".join(a) for a, _ in TRAIN_ERRORS])
def test_train_bad_input(tmp_path, args, fragments):
    out = tmp_path / "out"
    proc = run_here("train", *args, "--no-progress", "--out", out)
    assert_one_line_error(proc, *fragments)
    assert not (out / "summary.json").exists()


def test_train_bad_hyperparameter_value_is_a_user_error(tmp_path):
    # n_steps=1 is a value SB3 rejects with an assertion; it is still the user's typo.
    out = tmp_path / "out"
    proc = run_here("train", ENV_ID, "--algo", "ppo", "--timesteps", "100", "--set", "n_steps=1",
                    "--no-progress", "--out", out)
    assert_one_line_error(proc, "n_steps")
    assert not (out / "summary.json").exists()


def test_error_message_is_printed_verbatim(tmp_path):
    # Messages quote what the user typed; text in brackets must not be read as console markup.
    proc = run_here("train", ENV_ID, "--reward", "[/tmp]", "--no-progress", "--out", tmp_path / "out")
    assert_one_line_error(proc, "[/tmp]")


def test_invalid_train_leaves_no_complete_run_folder(tmp_path):
    out = tmp_path / "out"
    proc = run_here("train", ENV_ID, "--algo", "td3", "--clip-range", "0.2", "--timesteps", "100",
                    "--no-progress", "--out", out)
    assert_one_line_error(proc, "PPO")
    # Settings are checked before the run folder is created.
    assert not out.exists()
    assert_one_line_error(run_here("evaluate", out, "--out", tmp_path / "ev"), str(out))


def test_invalid_train_keeps_a_finished_run_in_its_out_folder(ppo_run, tmp_path):
    # "Nothing already written is lost": a mistyped re-run into a finished run folder
    # must fail before touching it.
    out = tmp_path / "finished"
    shutil.copytree(ppo_run, out)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    proc = run_here("train", ENV_ID, "--algo", "sac", "--clip-range", "0.2", "--timesteps", "100",
                    "--no-progress", "--out", out)
    assert_one_line_error(proc, "PPO")
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert after == before


# ---- evaluate and plot -----------------------------------------------------------

@pytest.fixture
def unfinished_run(tmp_path):
    """A folder without summary.json (an interrupted run, or not a run at all)."""
    path = tmp_path / "unfinished"
    path.mkdir()
    (path / "config.toml").write_text('algo = "ppo"\n')
    return path


@pytest.fixture(params=["truncated", "garbage"])
def corrupt_run(request, ppo_run, tmp_path):
    """A finished PPO run folder whose policy.safetensors was damaged afterwards."""
    path = tmp_path / f"corrupt-{request.param}"
    shutil.copytree(ppo_run, path)
    weights = path / "policy.safetensors"
    data = weights.read_bytes()
    if request.param == "truncated":
        weights.write_bytes(data[: len(data) // 2])
    else:
        weights.write_bytes(data[:8] + b"not a json header at all" + data[32:])
    return path


def test_evaluate_missing_folder(tmp_path):
    missing = tmp_path / "no-such-run"
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", missing, "--out", out), "no-such-run")
    assert not (out / "summary.json").exists()


def test_evaluate_file_instead_of_folder(ppo_run, tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", ppo_run / "summary.json", "--out", out), "not a folder")
    assert not (out / "summary.json").exists()


def test_evaluate_unfinished_folder(unfinished_run, tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", unfinished_run, "--out", out), "summary.json")
    assert not (out / "summary.json").exists()


def test_evaluate_corrupt_weights(corrupt_run, tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", corrupt_run, "--episodes", "2", "--out", out), "policy.safetensors")
    assert not (out / "summary.json").exists()


def test_evaluate_corrupt_policy_json(ppo_run, tmp_path):
    run = tmp_path / "bad-json"
    shutil.copytree(ppo_run, run)
    (run / "policy.json").write_text('{"type": "sb3", ')
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", run, "--episodes", "2", "--out", out), "policy.json")
    assert not (out / "summary.json").exists()


def test_evaluate_with_wrong_history(ppo_run, tmp_path):
    out = tmp_path / "out"
    proc = run_here("evaluate", ppo_run, "--history", "3", "--episodes", "2", "--out", out)
    assert_one_line_error(proc, "--history")
    assert not (out / "summary.json").exists()


def test_evaluate_lqr_with_wrong_history(fast_run, tmp_path):
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", fast_run, "--history", "2", "--out", out), "history")
    assert not (out / "summary.json").exists()


EVALUATE_ERRORS = [
    (["pid"], ["--env"]),  # a built-in controller needs an env
    (["pidd", "--env", ENV_ID], ["pidd"]),
    (["pid", "--env", ENV_ID, "--episodes", "0"], ["--episodes"]),
    (["pid", "--env", ENV_ID, "--history", "2"], ["8"]),  # 4 default gains, 8 observation elements
    (["pid:kp=[1,20,0]", "--env", ENV_ID], ["kp", "4"]),
    (["pid", "--env", "InvertedPendulm-v5"], ["InvertedPendulum-v5"]),
    (["pid", "--env", ENV_ID, "--delay", "0.01"], ["0.01"]),
]


@pytest.mark.parametrize("args, fragments", EVALUATE_ERRORS, ids=[" ".join(a) for a, _ in EVALUATE_ERRORS])
def test_evaluate_bad_input(tmp_path, args, fragments):
    out = tmp_path / "out"
    assert_one_line_error(run_here("evaluate", *args, "--out", out), *fragments)
    assert not (out / "summary.json").exists()


def test_plot_missing_folder(tmp_path):
    assert_one_line_error(run_here("plot", tmp_path / "no-such-run"), "no-such-run")


def test_plot_file_instead_of_folder(ppo_run):
    assert_one_line_error(run_here("plot", ppo_run / "config.toml"), "not a folder")


def test_plot_unfinished_folder(unfinished_run):
    assert_one_line_error(run_here("plot", unfinished_run), "summary.json")
    assert not (unfinished_run / "plots").exists()


def test_plot_corrupt_weights(ppo_run, tmp_path):
    run = tmp_path / "corrupt"
    shutil.copytree(ppo_run, run)
    (run / "policy.safetensors").write_bytes(b"")
    assert_one_line_error(run_here("plot", run), "policy.safetensors")


# ---- recipes -----------------------------------------------------------------------

RECIPES = {
    "typo-field": ("""
        name = "t"
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        timestep = 100
        """, ["timestep", "timesteps", "typo-field.toml"]),
    "typo-defaults": ("""
        name = "t"
        [defaults]
        envv = "InvertedPendulum-v5"
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulum-v5"
        """, ["[defaults]", "envv", "typo-defaults.toml"]),
    "bad-value": ("""
        name = "t"
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        timesteps = "many"
        """, ["timesteps", "bad-value.toml"]),
    "unknown-step": ("""
        name = "t"
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        [[steps]]
        name = "b"
        kind = "evaluate"
        policy = "@nothere"
        """, ["@nothere", "unknown-step.toml"]),
    "invalid-toml": ("""
        name = "t
        [[steps]
        """, ["TOML", "invalid-toml.toml"]),
}


@pytest.mark.parametrize("case", sorted(RECIPES))
def test_bad_recipe(tmp_path, case):
    text, fragments = RECIPES[case]
    path = tmp_path / f"{case}.toml"
    path.write_text(textwrap.dedent(text))
    out = tmp_path / "study"
    assert_one_line_error(run_here("run", path, "--out", out), *fragments)
    assert not out.exists()  # validated before anything ran


@pytest.mark.parametrize(
    "recipe, fragments", [("pendulm", ["pendulm", "pendulum"]), ("missing.toml", ["missing.toml"])]
)
def test_unknown_recipe(tmp_path, recipe, fragments):
    out = tmp_path / "study"
    assert_one_line_error(run_here("run", recipe, "--out", out, cwd=tmp_path), *fragments)
    assert not out.exists()


def test_successful_command_prints_no_error(tmp_path):
    # The contrast to everything above: a valid command exits 0 and prints no "error:".
    out = tmp_path / "ok"
    proc = run_cli("evaluate", "pid", "--env", ENV_ID, "--episodes", "1", "--out", out)
    assert_ok(proc)
    assert "error" not in proc.stderr.lower()
    assert read_summary(out)["return_mean"] == 1000.0


def test_the_command_line_starts_without_the_plotting_and_learning_libraries():
    """Every `motorlab` process (a command, a worker, each sweep trial) reads every command's settings when
    it starts: matplotlib, torch, SB3, scikit-learn and MuJoCo are imported where a command runs, not there."""
    import subprocess
    import sys

    heavy = ("matplotlib", "torch", "stable_baselines3", "sklearn", "ray", "optuna", "mujoco")
    proc = subprocess.run([sys.executable, "-c", "import sys, motorlab.cli, motorlab.worker; "
                           f"print(sorted(m for m in {heavy!r} if m in sys.modules))"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]", proc.stdout
