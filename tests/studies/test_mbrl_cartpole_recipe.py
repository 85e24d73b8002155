"""The `mbrl-cartpole` study: the PETS loop and SAC on CartpoleSwingup-v0, several seeds each, and
their evaluation curves compared (tiny budgets: the pipeline and its files, not a swing-up)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from motorlab.recipes import load_recipe
from tests.helpers import assert_ok, assert_png, read_summary, run_cli, scaled_recipe


def last_evaluation(path, step: str) -> tuple[float, float]:
    """(env steps, eval_return_mean) of the last row of a metrics.csv or curve.csv with an evaluation."""
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["eval_return_mean"] not in ("", None)]
    return float(rows[-1][step]), float(rows[-1]["eval_return_mean"])


def test_the_bundled_recipe_runs_the_loop_and_sac_for_several_seeds():
    recipe = load_recipe("mbrl-cartpole")
    steps = {s.name: s for s in recipe.steps}
    assert [s.kind.name for s in recipe.steps] == ["mbrl", "train", "compare"]
    loop, sac = steps["loop"], steps["sac"]
    assert loop.seeds == sac.seeds == [0, 1, 2, 3, 4]  # 5 seeds per arm
    assert loop.settings.env.id == sac.settings.env.id == "CartpoleSwingup-v0"
    assert loop.settings.rounds * loop.settings.episodes_per_round * 200 == 3000  # the loop's env steps
    assert sac.settings.algo == "sac" and sac.settings.timesteps == 30000 and sac.settings.eval_every == 1000
    assert steps["curves"].settings.curve == "evaluation"
    assert steps["curves"].settings.groups == {"PETS loop": ["@loop"], "SAC": ["@sac"]}


@pytest.mark.fast  # make test-fast: this workflow's end-to-end test
def test_scaled_study_compares_evaluation_curves(tmp_path):
    path = scaled_recipe("mbrl-cartpole", tmp_path)
    out = tmp_path / "out"
    assert_ok(run_cli("run", path, "--out", out))
    for step in ("loop", "sac"):
        for seed in (0, 1):
            assert (out / step / f"seed{seed}" / "summary.json").is_file(), (step, seed)
    loops = [out / "loop" / f"seed{k}" for k in (0, 1)]
    assert all(read_summary(d)["env_steps"] == 400 for d in loops)  # 2 rounds of one 200-step episode
    curves = read_summary(out / "curves")
    assert curves["PETS loop.seeds"] == 2 and curves["SAC.seeds"] == 2
    assert_png(out / "curves" / "plots" / "learning_curves.png")
    # both end at 400 env steps: the curves' last point is the mean of each seed's last evaluation
    pets = [last_evaluation(d / "curve.csv", "env_steps") for d in loops]
    sac = [last_evaluation(out / "sac" / f"seed{k}" / "metrics.csv", "timesteps") for k in (0, 1)]
    assert {s for s, _ in pets + sac} == {400.0}
    assert curves["PETS loop.final_eval_return_mean"] == pytest.approx(np.mean([v for _, v in pets]))
    assert curves["SAC.final_eval_return_mean"] == pytest.approx(np.mean([v for _, v in sac]))
    # the loop's final return is its score: rliable compares it with SAC's
    assert curves["PETS loop.final_return_mean"] == pytest.approx(
        np.mean([read_summary(d)["final_return_mean"] for d in loops]))
    assert "PETS loop.final_return_p_better_than[SAC]" in curves
    study = read_summary(out)
    assert study["loop.seeds"] == 2 and study["loop.env_steps"] == 400
    assert "SAC" in (out / "table.txt").read_text()
