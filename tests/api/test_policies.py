"""The Python API (motorlab.api): the same run folders as the CLI, read both ways; the same errors;
results that show in Jupyter; every workflow's functions on tiny budgets."""

from __future__ import annotations

import json
from html import escape

import numpy as np
import pytest

import motorlab
from motorlab.api import MotorlabError, Result, Run, Study, Sweep, Tune
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_cli

TINY = {"timesteps": 256, "hyperparams": {"n_steps": 128, "batch_size": 64}}
LQR_RECIPE = """name = "tiny"
description = "LQR balancing, one step"

[defaults]
env = "InvertedPendulum-v5"

[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"
episodes = 2

[[steps]]
name = "lqr"
kind = "train"
preset = "fast"
timesteps = 1500
until_solved = true
"""


@pytest.fixture(scope="module")
def api_run(tmp_path_factory) -> Run:
    """A PPO run trained through the API."""
    return motorlab.train(ENV_ID, "ppo", seed=3, out=tmp_path_factory.mktemp("api") / "ppo", progress=False, **TINY)


def test_what_the_api_trains_the_cli_evaluates_alike(api_run, tmp_path):
    assert isinstance(api_run, Run) and api_run.kind == "train"
    assert api_run.summary == read_summary(api_run.path)
    assert api_run.summary["timesteps"] == 256 and api_run.summary["seed"] == 3
    assert api_run.config["env"]["id"] == ENV_ID and api_run.config["hyperparams"]["n_steps"] == 128
    by_api = api_run.evaluate(episodes=3, delay=0.1, out=tmp_path / "api-eval", progress=False)
    assert_ok(run_cli("evaluate", api_run.path, "--episodes", "3", "--delay", "0.1", "--out", tmp_path / "cli-eval"))
    by_cli = read_summary(tmp_path / "cli-eval")
    for key in ("return_mean", "return_min", "episode_lengths", "success_rate"):
        assert by_api[key] == by_cli[key], key
    assert by_api.config == motorlab.load(tmp_path / "cli-eval").config


def test_what_the_cli_trains_the_api_reads(tmp_path):
    out = tmp_path / "cli-ppo"
    assert_ok(run_cli("train", ENV_ID, "--algo", "ppo", "--timesteps", "256", "--set", "n_steps=128",
                      "--set", "batch_size=64", "--seed", "5", "--out", out, "--no-progress"))
    assert_ok(run_cli("evaluate", out, "--episodes", "2", "--out", tmp_path / "cli-eval"))
    run = motorlab.load(out)
    assert isinstance(run, Run) and run.summary["seed"] == 5
    again = motorlab.evaluate(run, episodes=2, out=tmp_path / "api-eval", progress=False)
    assert again["episode_lengths"] == read_summary(tmp_path / "cli-eval")["episode_lengths"]
    assert isinstance(motorlab.load(tmp_path / "cli-eval"), Result)
    assert not isinstance(motorlab.load(tmp_path / "cli-eval"), Run)


def test_the_policy_acts_as_the_evaluation_did(api_run, tmp_path):
    """One episode rolled by hand with run.env() and run.policy gets the evaluation's return."""
    evaluated = api_run.evaluate(episodes=1, seed=11, out=tmp_path / "eval", progress=False)
    env = api_run.env()
    obs, _ = env.reset(seed=11)
    api_run.policy.reset()
    total, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(api_run.policy(obs))
        total, done = total + reward, terminated or truncated
    assert total == pytest.approx(evaluated["return_mean"])
    batch = api_run.policy(np.stack([obs, obs]))
    assert batch.shape == (2, *env.action_space.shape)


def test_errors_are_the_clis_messages(tmp_path):
    with pytest.raises(MotorlabError) as caught:
        motorlab.train(ENV_ID, timesteps=-5, out=tmp_path / "x")
    cli = assert_one_line_error(run_cli("train", ENV_ID, "--timesteps", "-5", "--out", tmp_path / "y"))
    assert cli == f"error: {caught.value}"
    with pytest.raises(MotorlabError, match="unknown setting --n-env"):
        motorlab.train(ENV_ID, n_env=2)
    with pytest.raises(MotorlabError, match="no env for 'pid'"):
        motorlab.evaluate("pid")
    with pytest.raises(MotorlabError, match="does not exist"):
        motorlab.load(tmp_path / "nothing")
    assert not (tmp_path / "x").exists()  # nothing written for a mistake


def test_results_show_their_numbers_and_plots_in_jupyter(api_run):
    figures = api_run.plot()
    assert {p.name for p in figures} == {"learning_curve.png", "observation_trace.png"}
    html = api_run._repr_html_()
    assert html.count("data:image/png;base64,") == len(api_run.figures) >= 2
    shown = [n for n in api_run.numbers if not n.setup]
    assert shown and all(f"<td style='text-align:right'>{escape(n.text)}</td>" in html for n in shown)
    assert "return" in repr(api_run) and str(api_run.path) in repr(api_run)


def test_video_from_python(api_run, tmp_path):
    videos = api_run.video(episodes=1, width=64, height=48, out=tmp_path / "videos")
    assert [p.suffix for p in videos] == [".mp4"] and videos[0].stat().st_size > 1000
    assert "<video" in motorlab.load(tmp_path / "videos")._repr_html_()


def test_forward_model_and_mpc_from_python(tmp_path):
    data = motorlab.api.dynamics.collect("Reacher-v5", 20, out=tmp_path / "data", workers=1, progress=False)
    model = motorlab.api.dynamics.fit(data, epochs=2, out=tmp_path / "model", progress=False)
    assert (model.path / "model.safetensors").is_file() and model.kind == "dynamics-fit"
    check = motorlab.api.dynamics.check(model, episodes=1, out=tmp_path / "check", progress=False)
    assert check.figures and check.kind == "dynamics-check"
    control = motorlab.mpc("Reacher-v5", model, episodes=1, horizon=3, population=16, iterations=1, elites=4,
                           out=tmp_path / "mpc", progress=False)
    assert control.summary["episodes"] == 1 and control.config["model"] == str(model.path)
    # the CLI reads the API's model
    assert_ok(run_cli("dynamics", "check", model.path, "--episodes", "1", "--out", tmp_path / "cli-check"))


def test_synergies_from_python(api_run, tmp_path):
    acts = motorlab.api.synergies.collect(api_run, 4, signal="action", percentile=0, workers=1,
                                      out=tmp_path / "collect", progress=False)
    assert (acts.path / "activations.npz").is_file()
    vaf = motorlab.api.synergies.vaf(acts, out=tmp_path / "vaf")
    sar = motorlab.api.synergies.fit(acts, 1, out=tmp_path / "fit")
    assert vaf.kind == "vaf" and sar.summary["n_synergies"] == 1
    assert motorlab.api.synergies.load_sar(sar).n_synergies == 1  # the fit's sar.npz, found from its result


def test_a_recipe_a_sweep_and_a_search_from_python(tmp_path):
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(LQR_RECIPE)
    study = motorlab.run_recipe(recipe, tmp_path / "study")
    assert isinstance(study, Study) and set(study.steps) == {"pid", "lqr"}
    assert isinstance(study.steps["lqr"], Run) and study.summary["pid.return_mean"] == 1000
    assert "pid" in study.table and "<pre>" in study._repr_html_()
    assert isinstance(motorlab.load(study.path), Study)

    swept = motorlab.sweep(f"evaluate pid --env {ENV_ID} --episodes 2", seeds=2, out=tmp_path / "sweep")
    assert isinstance(swept, Sweep) and swept.summary["trials"] == 2
    assert json.loads((swept.path / "aggregate.json").read_text()) == swept.aggregate

    search = motorlab.tune(recipe, {"lqr.timesteps": "choice:1000,1500"}, trials=1, seeds=1,
                           objective="lqr.return_mean", pruner="none", fresh_seeds=0, sampler_seed=0,
                           out=tmp_path / "tune")
    assert isinstance(search, Tune) and len(search.trials) == 1
    assert search.best["lqr"]["timesteps"] in (1000, 1500)


def test_robustness_from_python_is_the_function_not_the_package(api_run, tmp_path):
    import motorlab.robustness_curves.curves  # noqa: F401  (the domain package, loaded: the name stays the API's)

    curves = motorlab.robustness(["pid", api_run], {"delay": [0, 0.1]}, episodes=1, workers=1, out=tmp_path / "r",
                                 progress=False)
    assert curves.kind == "robustness" and (curves.path / "curves.csv").is_file()
    lengths = motorlab.evaluate("pid", ENV_ID, episodes=1, env_kwargs={"reset_noise_scale": 0.0},
                                out=tmp_path / "e", progress=False)
    assert lengths.config["env"]["kwargs"] == {"reset_noise_scale": 0.0}


def test_the_apis_sweep_and_tune_take_their_defaults_from_the_commands_settings():
    """No default is typed twice: every setting the API's sweep and tune pass on defaults to None, and the
    command's settings model gives the value (what `motorlab sweep/tune --help` shows)."""
    import inspect

    from motorlab.sweeps.sweep_command import SWEEP
    from motorlab.tuning.tune_command import TUNE

    for function, command in ((motorlab.sweep, SWEEP), (motorlab.tune, TUNE)):
        params = inspect.signature(function).parameters
        shared = set(params) & set(command.settings.model_fields) - {"target", "space"}
        assert shared and all(params[p].default is None for p in shared), function.__name__


def test_a_sweep_takes_the_seeds_themselves_or_refuses_them_in_one_line(tmp_path):
    swept = motorlab.sweep(f"evaluate pid --env {ENV_ID} --episodes 1", seeds=[3, 5], out=tmp_path / "sweep")
    assert sorted(p.name for p in (swept.path / "default").iterdir() if p.name.startswith("seed")) == ["seed3", "seed5"]
    for bad in ([], [1, 1], [-1]):
        with pytest.raises(MotorlabError, match="distinct non-negative integers"):
            motorlab.sweep(f"evaluate pid --env {ENV_ID} --episodes 1", seeds=bad, out=tmp_path / "bad")
