"""`motorlab dynamics collect | fit | check` and `motorlab mpc` as a user runs them, and their bad inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.helpers import assert_ok, assert_one_line_error, assert_png, read_summary, run_cli, run_here


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory):
    root = tmp_path_factory.mktemp("reacher")
    assert_ok(run_cli("dynamics", "collect", "Reacher-v5", "--episodes", "300", "--out", root / "data"))
    assert_ok(run_cli("dynamics", "fit", root / "data", "--epochs", "3", "--batch-size", "500",
                      "--out", root / "model"))
    return root


def test_collect_fit_check_mpc(pipeline, tmp_path):
    data = read_summary(pipeline / "data")
    assert data["transitions"] == 300 * 50 and data["transitions_per_second"] > 0
    assert data["simulator"] == "closed-form" and data["state_size"] == 8

    fit = read_summary(pipeline / "model")
    assert 0 < fit["valid_mse"] < 1 and fit["wall_seconds"] > 0 and fit["epochs_run"] == 3
    model_json = json.loads((pipeline / "model" / "model.json").read_text())
    assert model_json["env_id"] == "Reacher-v5" and model_json["state_layout"] == "reacher"
    assert model_json["architecture"]["hidden"] == [200, 200]  # dynamics fit's default width
    assert_png(pipeline / "model" / "plots" / "loss.png")
    assert (pipeline / "model" / "metrics.csv").read_text().count("\n") == 4
    assert any((pipeline / "model" / "tensorboard").rglob("events.out.tfevents.*"))

    proc = run_cli("dynamics", "check", pipeline / "model", "--episodes", "2", "--out", tmp_path / "check")
    assert_ok(proc)
    check = read_summary(tmp_path / "check")
    assert check["tip_error_mean_h1"] < check["tip_error_mean_final"]  # open-loop error grows with the horizon
    for name in ("error_vs_horizon", "reach_error", "traces"):
        assert_png(tmp_path / "check" / "plots" / f"{name}.png")

    proc = run_cli("mpc", "Reacher-v5", "--model", pipeline / "model", "--episodes", "2", "--horizon", "3",
                   "--population", "16", "--iterations", "2", "--elites", "4", "--out", tmp_path / "mpc")
    assert_ok(proc)
    s = read_summary(tmp_path / "mpc")
    for key in ("return_mean", "return_std", "final_distance_mean", "plan_ms_median"):
        assert np.isfinite(s[key]), key
    assert s["final_distance_mean"] < 0.5 and s["plan_ms_median"] > 0 and "ms/step" in proc.stdout
    assert_png(tmp_path / "mpc" / "plots" / "distance.png")


@pytest.mark.parametrize("args, fragments", [
    (["dynamics", "collect", "Reacher-v9"], ["unknown env id", "Reacher-v5"]),
    (["dynamics", "collect", "Reacher-v5", "--episodes", "0"], ["--episodes 0", "greater than 0"]),
    (["dynamics", "collect", "Pendulum-v1", "--state", "reacher"], ["--state observation"]),
    (["dynamics", "collect", "Pendulum-v1", "--simulator", "closed-form"], ["Reacher", "use auto or gymnasium"]),
    (["dynamics", "collect", "Reacher-v5", "--simulator", "bullet"], ["--simulator 'bullet'", "closed-form", "'mujoco' or 'gymnasium'"]),
    (["dynamics", "fit", "missing.npz"], ["missing.npz is missing", "dynamics collect"]),
])
def test_bad_collect_and_fit_input(args, fragments, tmp_path):
    assert_one_line_error(run_here(*args, "--out", tmp_path / "out"), *fragments)
    assert not (tmp_path / "out").exists()


def test_bad_model_and_plan_input_leave_finished_runs_intact(pipeline, tmp_path):
    done = tmp_path / "done"
    assert_ok(run_cli("mpc", "Reacher-v5", "--model", pipeline / "model", "--episodes", "1", "--horizon", "2",
                      "--population", "8", "--iterations", "1", "--elites", "2", "--out", done))
    before = (done / "summary.json").read_bytes()
    cases = [
        (["--horizon", "0"], ["--horizon 0", "greater than 0"]),
        (["--population", "-5"], ["--population -5", "greater than 0"]),
        (["--elites", "50", "--population", "10"], ["cannot exceed --population"]),
        (["--optimizer", "adam"], ["--optimizer 'adam'"]),
    ]
    for extra, fragments in cases:
        assert_one_line_error(run_here("mpc", "Reacher-v5", "--model", pipeline / "model", *extra, "--out", done),
                              *fragments)
    assert_one_line_error(run_here("mpc", "Reacher-v4", "--model", pipeline / "model", "--out", done),
                          "models 'Reacher-v5', not 'Reacher-v4'")
    assert_one_line_error(run_here("mpc", "Reacher-v5", "--model", tmp_path / "nope", "--out", done),
                          "model.json is missing")
    assert (done / "summary.json").read_bytes() == before


def test_fit_rejects_bad_transitions_without_touching_the_run(pipeline, tmp_path):
    arrays = dict(np.load(pipeline / "data" / "transitions.npz"))
    arrays["next_states"] = arrays["next_states"][:, :5]
    np.savez(tmp_path / "bad.npz", **arrays)
    out = tmp_path / "model"
    out.mkdir()
    (out / "summary.json").write_text('{"kept": true}')
    assert_one_line_error(run_here("dynamics", "fit", tmp_path / "bad.npz", "--out", out), "differ in shape")
    assert_one_line_error(run_here("dynamics", "fit", pipeline / "data", "--hidden", "64,,-3", "--out", out),
                          "--hidden widths must be positive")
    assert_one_line_error(run_here("dynamics", "fit", pipeline / "data", "--patience", "2", "--valid-fraction", "0",
                                   "--out", out), "--patience needs")
    assert json.loads((out / "summary.json").read_text()) == {"kept": True}


# ---- the env setting: one EnvConfig, flat on the command line ----------------------------------


def test_collect_takes_env_settings_flat_and_records_them_as_an_env_config(tmp_path):
    """--history and --obs-noise act through the env's wrappers: the state is the stacked observations,
    config.toml records the env as EnvConfig does ([env] id, history, ...), and the transitions (and the
    model fit on them) remember the env they were collected under, for `dynamics check` and `mpc`."""
    import tomllib

    from motorlab.dynamics.transitions import load_transitions

    out = tmp_path / "data"
    assert_ok(run_here("dynamics", "collect", "InvertedPendulum-v5", "--episodes", "3", "--history", "3",
                       "--obs-noise", "0.01", "--workers", "1", "--out", out))
    s = read_summary(out)
    assert s["env_id"] == "InvertedPendulum-v5" and s["state_size"] == 3 * 4 and s["simulator"] == "gymnasium"
    env = tomllib.loads((out / "config.toml").read_text())["env"]
    assert (env["id"], env["history"], env["obs_noise"]) == ("InvertedPendulum-v5", 3, 0.01)
    assert load_transitions(out / "transitions.npz").meta["env"] == {"id": "InvertedPendulum-v5", "history": 3,
                                                                     "obs_noise": 0.01}
    # the bare Reacher under a delay: auto picks the env itself, and says so
    assert_ok(run_here("dynamics", "collect", "Reacher-v5", "--episodes", "2", "--delay", "0.05", "--workers", "1",
                       "--out", tmp_path / "delayed"))
    assert read_summary(tmp_path / "delayed")["simulator"] == "gymnasium"


@pytest.mark.parametrize("args, fragments", [
    (["Reacher-v5", "--simulator", "closed-form", "--delay", "0.05"],
     ["--simulator closed-form", "delay 0.05 s", "--simulator gymnasium"]),
    (["Reacher-v5", "--simulator", "mujoco", "--env-arg", "reward_control_weight=2"],
     ["--simulator mujoco", "cannot apply --env-arg", "--simulator gymnasium"]),
    (["Reacher-v5", "--state", "reacher", "--history", "2"], ["--history 2", "--state observation"]),
    (["--episodes", "2"], ["Missing argument 'ENV'"]),
])
def test_collect_refuses_env_settings_it_cannot_honour_in_one_line(args, fragments, tmp_path):
    assert_one_line_error(run_here("dynamics", "collect", *args, "--out", tmp_path / "out"), *fragments)
    assert not (tmp_path / "out").exists()


def test_collect_refuses_a_success_rule_and_keeps_its_own_fields():
    from motorlab.errors import MotorlabError
    from motorlab.kinds.dynamics import DYNAMICS_COLLECT

    with pytest.raises(MotorlabError, match=r"^env\.success 'final': dynamics collect counts no successes"):
        DYNAMICS_COLLECT.make(env="Reacher-v5", success="final")
    settings = DYNAMICS_COLLECT.make(env="Reacher-v5", state="observation", seed=3)
    assert (settings.env.id, settings.state, settings.seed) == ("Reacher-v5", "observation", 3)


def test_a_config_toml_with_the_env_as_a_string_still_loads(tmp_path):
    """Run folders written before the env was an EnvConfig recorded `env = "Reacher-v5"`."""
    import tomllib

    from motorlab.envs import EnvConfig
    from motorlab.kinds.dynamics import DYNAMICS_COLLECT

    old = ('env = "Reacher-v5"\nepisodes = 300\npolicy = "random"\nstate = "auto"\nsimulator = "auto"\n'
           'seed = 0\n')
    settings = DYNAMICS_COLLECT.validate(tomllib.loads(old))
    assert settings.env == EnvConfig(id="Reacher-v5") and settings.episodes == 300
    assert DYNAMICS_COLLECT.describe(settings) == "collect 300 random episodes of Reacher-v5"
