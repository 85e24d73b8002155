"""The SAR study as a recipe (the bundled sar-hand-quick, at the tests' scale): play -> collect ->
VAF -> fit -> SAR-RL vs RL-E2E -> zero-shot -> learning curves, each step in its own folder; a
re-run keeps every finished step."""

from __future__ import annotations

import io
import json
import statistics
import tomllib

import pytest
from rich.console import Console

from motorlab.api.synergies import load_sar
from motorlab.recipes import bundled, load_recipe, parse_recipe
from motorlab.runs import run_folders
from motorlab.studies import run_study
from tests.helpers import HAND_MUSCLES, assert_ok, assert_one_line_error, assert_png, read_summary, run_cli, run_here

# The bundled sar-hand-quick at the tests' scale (conftest.py's sar_hand_quick, run once for this
# file and test_bundled_reports.py): play -> collect -> VAF -> fit by VAF -> SAR-RL (phi 0.66) vs
# RL-E2E on two seeds each, the two chains trained at once -> zero-shot -> learning curves.
STEP_DIRS = ["play", "collect", "vaf", "fit", "sar-rl/seed0", "sar-rl/seed1", "rl-e2e/seed0", "rl-e2e/seed1",
             "zeroshot", "curves"]


@pytest.fixture(scope="module")
def study(sar_hand_quick):
    """(recipe file, study folder, the recipe's steps by name as written in the file)."""
    recipe, out = sar_hand_quick
    steps = {step["name"]: step for step in tomllib.loads(recipe.read_text())["steps"]}
    return recipe, out, steps


def test_every_step_has_its_folder(study):
    _, out, steps = study
    for d in STEP_DIRS:
        assert (out / d / "summary.json").is_file(), d
    assert (out / "collect" / "activations.npz").is_file()
    assert_png(out / "vaf" / "vaf.png")
    assert_png(out / "curves" / "plots" / "learning_curves.png")
    assert_png(out / "zeroshot" / "plots" / "zeroshot.png")
    assert not (out / "sar-rl" / "summary.json").exists()  # seeds, not the step, are runs
    sar = load_sar(out / "fit" / "sar.npz")
    # fit by VAF: the smallest N the VAF step found for the same threshold
    assert steps["fit"]["vaf"] == steps["vaf"]["threshold"]
    n = read_summary(out / "vaf")["n_for_threshold"]
    assert (sar.n_synergies, sar.n_muscles) == (n, HAND_MUSCLES) and 1 <= n < HAND_MUSCLES


def test_sar_rl_trains_in_the_fitted_synergy_space(study):
    _, out, steps = study
    sar_path = str((out / "fit" / "sar.npz").resolve())
    seeds, phi = steps["sar-rl"]["seeds"], steps["sar-rl"]["phi"]
    assert seeds == steps["rl-e2e"]["seeds"] and len(seeds) == 2 and 0 < phi < 1
    for seed in seeds:
        cfg = tomllib.loads((out / "sar-rl" / f"seed{seed}" / "config.toml").read_text())
        assert cfg["env"]["sar"] == sar_path and cfg["env"]["phi"] == pytest.approx(phi) and cfg["seed"] == seed
        e2e = tomllib.loads((out / "rl-e2e" / f"seed{seed}" / "config.toml").read_text())
        assert "sar" not in e2e["env"] and e2e["seed"] == seed
    n = load_sar(out / "fit" / "sar.npz").n_synergies
    policy = json.loads((out / "sar-rl" / "seed0" / "policy.json").read_text())
    assert policy["action_space"]["shape"] == [n + HAND_MUSCLES]  # [synergies, raw muscles]
    e2e_policy = json.loads((out / "rl-e2e" / "seed0" / "policy.json").read_text())
    assert e2e_policy["action_space"]["shape"] == [HAND_MUSCLES]


def test_study_summary(study):
    _, out, steps = study
    s = read_summary(out)
    seeds = steps["sar-rl"]["seeds"]
    assert s["steps"] == ["play", "collect", "vaf", "fit", "sar-rl", "rl-e2e", "zeroshot", "curves"]
    assert s["fit.n_synergies"] == load_sar(out / "fit" / "sar.npz").n_synergies and s["fit.n_muscles"] == HAND_MUSCLES
    assert s["collect.episodes_kept"] == steps["collect"]["episodes"] and s["collect.n_muscles"] == HAND_MUSCLES
    assert s["vaf.n_for_threshold"] == read_summary(out / "vaf")["n_for_threshold"]
    assert s["sar-rl.seeds"] == 2 and s["rl-e2e.seeds"] == 2
    envs = steps["zeroshot"]["envs"]
    assert "myoHandReorientID-v0" in envs
    for step in ("sar-rl", "rl-e2e"):
        for env in envs:
            per_seed = [s[f"zeroshot.{step}/seed{k}.{env}.success_rate"] for k in seeds]
            mean = s[f"zeroshot.{step}.{env}.success_rate_mean"]
            assert 0.0 <= mean <= 1.0 and mean == pytest.approx(statistics.fmean(per_seed))
        returns = [read_summary(out / step / f"seed{k}")["eval_return_mean"] for k in seeds]
        assert s[f"{step}.return_mean"] == pytest.approx(statistics.fmean(returns))
    assert s["curves.SAR-RL.seeds"] == 2 and s["curves.RL-E2E.seeds"] == 2
    assert (out / "table.txt").read_text().startswith("step")


def test_rerun_keeps_every_step(study):
    recipe, out, _ = study
    before = {d: (out / d / "summary.json").stat().st_mtime_ns for d in STEP_DIRS}
    sar_bytes = (out / "fit" / "sar.npz").read_bytes()
    proc = run_cli("run", recipe, "--out", out, "--resume", timeout=600)
    assert_ok(proc)
    assert proc.stdout.count("already done") == len(STEP_DIRS)
    assert {d: (out / d / "summary.json").stat().st_mtime_ns for d in STEP_DIRS} == before
    assert (out / "fit" / "sar.npz").read_bytes() == sar_bytes


# ---- recipe mistakes --------------------------------------------------------------------

HEAD = """
name = "broken"
[[steps]]
name = "play"
kind = "train"
env = "InvertedPendulum-v5"
timesteps = 100
[[steps]]
name = "collect"
kind = "collect"
run = "@play"
"""

BROKEN = [
    ("""
[[steps]]
name = "sar-rl"
kind = "train"
env = "InvertedPendulum-v5"
sar = "@collect"
""", ["steps[2] (sar-rl)", "'@collect'", "fit step"]),
    ("""
[[steps]]
name = "vaf"
kind = "vaf"
activations = "@play"
""", ["steps[2] (vaf)", "'@play'", "names no earlier collect or import-emg step", "steps so far: collect"]),
    ("""
[[steps]]
name = "fit"
kind = "fitt"
activations = "@collect"
""", ["steps[2] (fit)", "unknown kind 'fitt'", "did you mean fit"]),
]


@pytest.mark.parametrize("tail, fragments", BROKEN, ids=["sar-names-collect", "activations-names-train", "fitt"])
def test_recipe_mistakes(tmp_path, tail, fragments):
    path = tmp_path / "broken.toml"
    path.write_text(HEAD + tail)
    proc = run_here("run", path, "--out", tmp_path / "out")
    assert_one_line_error(proc, str(path), *fragments)
    assert not (tmp_path / "out").exists()


# ---- the bundled SAR recipes ------------------------------------------------------------

@pytest.mark.parametrize("name", ["sar-hand", "sar-hand-reference", "sar-hand-quick", "sar-legs", "sar-legs-reference",
                                  "sar-legs-quick"])
def test_bundled_sar_recipes_parse(name):
    raw = tomllib.loads(bundled()[name].read_text())
    recipe = load_recipe(name)
    assert recipe.name == name
    assert [(s.name, s.kind.name) for s in recipe.steps] == [(r["name"], r["kind"]) for r in raw["steps"]]
    kinds = [s.kind.name for s in recipe.steps]
    assert kinds[:4] == ["train", "collect", "vaf", "fit"] and kinds[-1] == "compare"
    assert ("zeroshot" in kinds) == name.startswith("sar-hand")
    by_name = {s.name: s for s in recipe.steps}
    sar_rl = by_name["sar-rl"]
    assert sar_rl.fields["sar"] == "@fit" and sar_rl.inputs() == ["fit"]  # resolved when the study runs
    assert sar_rl.settings.env.phi == pytest.approx(next(r for r in raw["steps"] if r["name"] == "sar-rl")["phi"])
    assert by_name["rl-e2e"].settings.env.sar is None and by_name["rl-e2e"].inputs() == []
    assert by_name["collect"].settings.run == "@play"
    for r in raw["steps"]:
        if r["kind"] == "train":
            step = by_name[r["name"]]
            env_id = {"${terrain}": "myoLegRoughTerrainWalk-v0"}.get(r["env"], r["env"])  # the input's default
            assert step.settings.env.id == env_id and step.settings.timesteps == r["timesteps"]
            assert step.settings.algo == "sac"  # the SAR study's SAC presets


def test_fast_preset_changes_only_the_compute_per_env_step():
    from motorlab.rl.config import resolve

    def train_settings(preset):
        cfg = resolve({"preset": preset, "env": {"id": "myoHandReorient8-v0"}})
        return cfg.model_dump(exclude={"preset"})

    ref, fast = train_settings("sar-sac"), train_settings("sar-sac-fast")
    compute = {"train_freq", "gradient_steps"}
    assert {k: v for k, v in fast["hyperparams"].items() if k not in compute} == \
           {k: v for k, v in ref["hyperparams"].items() if k not in compute}
    assert {k for k in ref if ref[k] != fast[k]} == {"n_envs", "torch_threads", "hyperparams"}
    # one gradient step per 25 env steps; SB3 counts train_freq in steps of all n_envs envs
    assert fast["hyperparams"]["gradient_steps"] / (fast["hyperparams"]["train_freq"] * fast["n_envs"]) == 1 / 25


def test_sar_hand_is_the_reference_study_with_the_fast_preset():
    fast, ref = load_recipe("sar-hand"), load_recipe("sar-hand-reference")
    assert [(s.name, s.kind) for s in fast.steps] == [(s.name, s.kind) for s in ref.steps]
    for f, r in zip(fast.steps, ref.steps):
        if f.kind.name == "train":
            assert (f.settings.env, f.settings.timesteps) == (r.settings.env, r.settings.timesteps)
            assert f.settings.hyperparams["learning_starts"] == r.settings.hyperparams["learning_starts"]
            assert (f.settings.n_envs, r.settings.n_envs) == (4, 1)
            assert f.settings.torch_threads == r.settings.torch_threads == 1  # two trainings at once share 2 cores
        else:
            assert f.settings == r.settings


# ---- resuming after an upstream step changed ---------------------------------------------

def tiny_sar_study(n_synergies: int) -> str:
    return f"""
name = "sar-tiny"
[defaults]
preset = "sar-sac"
hyperparams = {{ learning_starts = 100, gradient_steps = 2, policy_kwargs = {{ net_arch = {{ pi = [16], qf = [16] }} }} }}
solve_episodes = 1
progress = false

[[steps]]
name = "play"
kind = "train"
env = "myoHandReorient8-v0"
timesteps = 150

[[steps]]
name = "collect"
kind = "collect"
run = "@play"
episodes = 2
preview = 2
percentile = 0
workers = 1

[[steps]]
name = "fit"
kind = "fit"
activations = "@collect"
n_synergies = {n_synergies}

[[steps]]
name = "sar-rl"
kind = "train"
env = "myoHandReorient8-v0"
sar = "@fit"
timesteps = 120
"""


def test_rerun_retrains_on_a_refitted_sar(tmp_path):
    """Re-running after a step's settings changed must not keep later steps built on its
    old output: a SAR refitted with fewer synergies needs a new synergy-space policy."""
    out = tmp_path / "study"
    quiet = Console(file=io.StringIO())
    run_study(parse_recipe(tiny_sar_study(3), "tiny.toml"), out, console=quiet)
    assert load_sar(out / "fit" / "sar.npz").n_synergies == 3
    with run_folders("resume"):  # a finished study is redone only when asked: --resume
        run_study(parse_recipe(tiny_sar_study(2), "tiny.toml"), out, console=quiet)
    assert load_sar(out / "fit" / "sar.npz").n_synergies == 2
    policy = json.loads((out / "sar-rl" / "policy.json").read_text())
    assert policy["action_space"]["shape"] == [2]
