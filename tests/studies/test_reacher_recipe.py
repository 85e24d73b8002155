"""The model-based study as a recipe: collect -> fit -> check -> MPC, its table and summary, re-runs."""

from __future__ import annotations

import pytest

from motorlab.recipes import load_recipe
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli, run_here

TINY = """
name = "reacher-tiny"
description = "forward model + MPC, tiny"

[[steps]]
name = "collect"
kind = "dynamics-collect"
env = "Reacher-v5"
episodes = 200

[[steps]]
name = "model"
kind = "dynamics-fit"
transitions = "@collect"
epochs = 2
batch_size = 500

[[steps]]
name = "check"
kind = "dynamics-check"
model = "@model"
episodes = 2

[[steps]]
name = "mpc"
kind = "mpc"
env = "Reacher-v5"
model = "@model"
episodes = 2
horizon = 3
population = 16
iterations = 2
elites = 4
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("reacher-study")
    (root / "tiny.toml").write_text(TINY)
    proc = run_cli("run", root / "tiny.toml", "--out", root / "out")
    assert_ok(proc)
    return root, proc


@pytest.mark.fast  # make test-fast: this workflow's end-to-end test
def test_study_runs_every_step(study):
    root, _ = study
    out = root / "out"
    for step in ("collect", "model", "check", "mpc"):
        assert (out / step / "summary.json").is_file(), step
    s = read_summary(out)
    assert s["collect.transitions"] == 200 * 50 and s["model.epochs_run"] == 2
    assert s["mpc.return_mean"] == read_summary(out / "mpc")["return_mean"]
    assert "check.tip_error_mean_h1" in s and s["mpc.plan_ms_median"] > 0
    table = (out / "table.txt").read_text()
    assert "transitions 10,000" in table and "final distance" in table and "valid MSE" in table


def test_rerun_keeps_finished_steps(study):
    root, _ = study
    before = {p: (root / "out" / p / "summary.json").stat().st_mtime_ns for p in ("collect", "model", "mpc")}
    proc = run_cli("run", root / "tiny.toml", "--out", root / "out", "--resume")
    assert_ok(proc)
    assert proc.stdout.count("already done with these settings") == 4
    assert before == {p: (root / "out" / p / "summary.json").stat().st_mtime_ns for p in before}


@pytest.mark.parametrize("name", ["reacher", "reacher-quick"])
def test_bundled_reacher_recipes_parse(name):
    recipe = load_recipe(name)
    assert [s.kind.name for s in recipe.steps] == ["dynamics-collect", "dynamics-fit", "dynamics-check", "mpc"]


@pytest.mark.parametrize("change, fragments", [
    (('model = "@model"\nepisodes = 2\nhorizon', 'model = "@collect"\nepisodes = 2\nhorizon'),
     ["model '@collect' names no earlier dynamics-fit or mbrl step"]),
    (("iterations = 2", 'iterations = 2\noptimizer = "adam"'), ["optimizer"]),
    (("horizon = 3", "horizon = 0"), ["horizon", "greater than 0"]),
    (('env = "Reacher-v5"\nepisodes = 200', 'env = "Reacher-v9"\nepisodes = 200'), ["unknown env id"]),
])
def test_recipe_mistakes(tmp_path, change, fragments):
    assert change[0] in TINY
    (tmp_path / "bad.toml").write_text(TINY.replace(*change))
    assert_one_line_error(run_here("run", tmp_path / "bad.toml", "--out", tmp_path / "out"), *fragments)
    assert not (tmp_path / "out" / "summary.json").exists()
