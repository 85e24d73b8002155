"""The SAR locomotion study: `sar-legs-quick` end to end, the published-SAR shortcut on the real
published locomotion SAR, and the terrain as a recipe input (tiny budgets: the pipeline, its
files and its settings, not walking)."""

from __future__ import annotations

import tomllib

import pytest

from motorlab.api.synergies import load_sar
from motorlab.recipes import load_recipe
from tests.helpers import assert_ok, assert_one_line_error, read_summary, run_cli, run_here, scaled_recipe

TERRAINS = {"rough": "myoLegRoughTerrainWalk-v0", "hilly": "myoLegHillyTerrainWalk-v0",
            "stairs": "myoLegStairTerrainWalk-v0"}
# a SAR-RL and an RL-E2E run of a few hundred env steps each, in this test's budget
TINY = ["--set", "timesteps=400", "--set", "n_envs=1", "--set", "eval_every=100000", "--set", "solve_episodes=2",
        "--set", "hyperparams={learning_starts = 100, gradient_steps = 1, train_freq = 50}"]


@pytest.mark.parametrize("recipe", ["sar-legs", "sar-legs-reference", "sar-legs-quick", "sar-legs-published"])
@pytest.mark.parametrize("terrain", sorted(TERRAINS))
def test_the_terrain_is_an_input_with_a_default(recipe, terrain, request):
    given = {"sar": str(request.getfixturevalue("legs_sar"))} if recipe == "sar-legs-published" else {}
    default = load_recipe(recipe, given)
    picked = load_recipe(recipe, {**given, "terrain": terrain})
    walkers = [s.name for s in default.steps if s.name in ("sar-rl", "rl-e2e")]
    assert walkers == ["sar-rl", "rl-e2e"]
    for name in walkers:
        assert next(s for s in default.steps if s.name == name).settings.env.id == TERRAINS["rough"]
        assert next(s for s in picked.steps if s.name == name).settings.env.id == TERRAINS[terrain]
    play = [s for s in picked.steps if s.name == "play"]
    assert all(s.settings.env.id == "myoLegWalk-v0" for s in play)  # play stays on flat ground


def test_sar_legs_is_the_reference_study_at_affordable_settings():
    fast, reference = load_recipe("sar-legs"), load_recipe("sar-legs-reference")
    budgets = {s.name: getattr(s.settings, "timesteps", None) for s in reference.steps}
    assert {s.name: getattr(s.settings, "timesteps", None) for s in fast.steps} == budgets
    assert budgets["play"] + budgets["sar-rl"] == budgets["rl-e2e"] == 4_000_000  # equal env steps per arm
    ref_rl = next(s for s in reference.steps if s.name == "rl-e2e").settings
    fast_rl = next(s for s in fast.steps if s.name == "rl-e2e").settings
    assert ref_rl.hyperparams["gradient_steps"] == -1 and ref_rl.n_envs == 1  # one update per env step
    for step in ("play", "sar-rl", "rl-e2e"):  # one gradient step per 25 env steps, one env, one thread
        settings = next(s for s in fast.steps if s.name == step).settings
        assert settings.hyperparams["train_freq"] == 25 and settings.hyperparams["gradient_steps"] == 1
        assert settings.n_envs == 1 and settings.torch_threads == 1
    for key in ("policy_kwargs", "batch_size", "buffer_size", "tau", "gamma"):  # the same SAC otherwise
        assert fast_rl.hyperparams[key] == ref_rl.hyperparams[key]
    assert fast_rl.lr == ref_rl.lr and fast_rl.normalize and ref_rl.normalize
    sar_rl = next(s for s in fast.steps if s.name == "sar-rl").settings
    assert sar_rl.env.phi == 1.0 and sar_rl.hyperparams["learning_starts"] == 5000


@pytest.mark.parametrize("given, fragments", [
    ({"terrain": "hily"}, ["terrain=hily", "rough | hilly | stairs", "did you mean hilly"]),
    ({"terain": "hilly"}, ["'terain'", "did you mean terrain"]),
    ({"sar-rl.phy": "0.5"}, ["no field 'phy'", "did you mean phi"]),
    ({"sarrl.phi": "0.5"}, ["no step 'sarrl'", "did you mean sar-rl"]),
])
def test_bad_overrides_name_the_problem(given, fragments, tmp_path):
    args = [x for key, value in given.items() for x in ("--set", f"{key}={value}")]
    assert_one_line_error(run_here("run", "sar-legs", *args, "--out", tmp_path / "out"), *fragments)
    assert not (tmp_path / "out").exists()


def test_the_published_recipes_need_their_sar(tmp_path):
    for recipe, muscles in (("sar-legs-published", "locomotion"), ("sar-hand-published", "manipulation")):
        proc = run_here("run", recipe, "--out", tmp_path / "out")
        assert_one_line_error(proc, "needs --set sar=VALUE", f"{muscles} --trust")
        assert not (tmp_path / "out").exists()


def test_published_locomotion_sar_recipe_runs(legs_sar, tmp_path):
    """The published SAR (20 synergies x 80 leg muscles, ../shared/data), imported once, given on the
    command line: no play, collect or fit; SAR-RL acts through it on the terrain picked."""
    sar = load_sar(legs_sar)
    assert (sar.n_synergies, sar.n_muscles) == (20, 80)
    out = tmp_path / "study"
    # one seed per arm here (the recipe's 5 are for evidence, not for this test of its pipeline)
    proc = run_cli("run", "sar-legs-published", "--set", f"sar={legs_sar}", "--set", "terrain=hilly", *TINY,
                   "--set", "seeds=1", "--out", out, timeout=600)
    assert_ok(proc)
    assert sorted(p.relative_to(out).as_posix() for p in out.glob("**/summary.json")) == \
        ["curves/summary.json", "rl-e2e/seed0/summary.json", "sar-rl/seed0/summary.json", "summary.json"]
    sar_rl, e2e = read_summary(out / "sar-rl" / "seed0"), read_summary(out / "rl-e2e" / "seed0")
    assert sar_rl["env_id"] == e2e["env_id"] == "myoLegHillyTerrainWalk-v0"
    assert sar_rl["timesteps"] == e2e["timesteps"] == 400
    config = (out / "sar-rl" / "seed0" / "config.toml").read_text()
    assert str(legs_sar) in config and "phi = 1.0" in config
    assert tomllib.loads((out / "rl-e2e" / "seed0" / "config.toml").read_text())["env"].get("sar") is None  # SAR-RL's only
    assert sar_rl["success_by"] == '"solved" at the final step'
    assert 0.0 <= sar_rl["eval_success_rate"] <= 1.0 and sar_rl["eval_episodes"] == 2


def test_sar_legs_quick_end_to_end(tmp_path):
    """Every step of the legs study, play to curves, on budgets far too small to walk."""
    recipe = scaled_recipe("sar-legs-quick", tmp_path)
    out = tmp_path / "study"
    assert_ok(run_cli("run", recipe, "--set", "terrain=stairs", "--out", out, timeout=900))
    summary = read_summary(out)
    for step in ("play", "collect", "vaf", "fit", "sar-rl", "rl-e2e", "curves"):
        assert (out / step / "summary.json").is_file(), step
    sar = load_sar(out / "fit" / "sar.npz")
    assert (sar.n_synergies, sar.n_muscles) == (20, 80)
    assert read_summary(out / "play")["env_id"] == "myoLegWalk-v0"
    assert read_summary(out / "sar-rl")["env_id"] == read_summary(out / "rl-e2e")["env_id"] == TERRAINS["stairs"]
    assert "sar-rl.success_rate" in summary and "rl-e2e.success_rate" in summary
    assert (out / "report.html").is_file() and (out / "curves" / "plots" / "learning_curves.png").is_file()
