"""Recipes: the bundled pendulum study parses; recipe validation; a small study runs
end to end from the CLI, and re-running it keeps the steps that already finished."""

from __future__ import annotations

import json
import textwrap
import tomllib
from pathlib import Path

import pytest

from motorlab.errors import MotorlabError
from motorlab.recipes import bundled, load_recipe, parse_recipe, refs_in, set_fields
from tests.helpers import assert_ok, assert_png, read_summary, run_cli

pytestmark = pytest.mark.fast  # make test-fast: cheap, unit-level

# ---- the bundled recipe ------------------------------------------------------------


def test_pendulum_recipe_is_bundled():
    assert "pendulum" in bundled()
    assert bundled()["pendulum"].is_file()


def test_pendulum_recipe_parses():
    raw = tomllib.loads(bundled()["pendulum"].read_text())
    recipe = load_recipe("pendulum")
    assert recipe.name == "pendulum"
    assert len(recipe.steps) >= 7
    # Every [[steps]] table became one validated step, in order, of the kind it names.
    assert [(s.name, s.kind.name) for s in recipe.steps] == [(r["name"], r["kind"]) for r in raw["steps"]]
    kinds = {s.kind.name for s in recipe.steps}
    assert kinds == {"train", "evaluate", "robustness"}
    by_name = {s.name: s for s in recipe.steps}
    for r, step in zip(raw["steps"], recipe.steps):
        if step.kind.name == "robustness":  # its env is what it sets on top of each policy's own
            assert step.settings.config()["env"] == {"id": raw["defaults"]["env"], **({"delay": r["delay"]} if "delay" in r else {})}
            assert step.settings.episodes == r["episodes"]
            assert {"ppo-delay-history", "fast-delay"} <= set(step.inputs())
            continue
        # [defaults] reach every step unless the step sets the field itself.
        env = step.settings.env
        assert env.id == r.get("env", raw["defaults"]["env"])
        assert env.delay == r.get("delay")
        assert env.history == r.get("history", 1)
        assert step.settings.seed == r.get("seed", raw["defaults"]["seed"])
        if step.kind.name == "train":
            assert step.settings.timesteps == r["timesteps"]
            assert step.settings.until_solved == r.get("until_solved", False)
            assert step.settings.preset == r.get("preset")
            if r.get("preset") == "fast":
                assert step.settings.algo == "lqr"
            elif r.get("preset") == "sb3-ppo":
                assert step.settings.algo == "ppo"
        else:
            assert step.settings.episodes == r.get("episodes", raw["defaults"]["episodes"])
            if r["policy"].startswith("@"):
                # A reference names an earlier train step; evaluation starts from its env.
                (ref,) = [by_name[name] for name in step.inputs()]
                assert ref.kind.name == "train"
                assert recipe.steps.index(ref) < recipe.steps.index(step)
                assert step.settings.env.history == ref.settings.env.history
            else:
                assert step.settings.policy == r["policy"]
    # The study compares PID, PPO and the fast preset, with and without delay.
    assert any(s.kind.name == "evaluate" and s.settings.policy == "pid" for s in recipe.steps)
    trained = [s.settings for s in recipe.steps if s.kind.name == "train"]
    assert {"ppo", "lqr"} <= {t.algo for t in trained}
    assert any(t.env.delay for t in trained) and any(t.env.history > 1 for t in trained)


def test_load_recipe_by_path(tmp_path):
    path = tmp_path / "copy.toml"
    path.write_text(bundled()["pendulum"].read_text())
    recipe = load_recipe(str(path))
    assert recipe.source == str(path)
    assert [s.name for s in recipe.steps] == [s.name for s in load_recipe("pendulum").steps]


# ---- validation (in-process; the CLI's exit code is covered in test_cli_errors.py) ----

def test_defaults_and_references_resolve():
    recipe = parse_recipe(textwrap.dedent("""
        name = "r"
        [defaults]
        env = "InvertedPendulum-v5"
        seed = 4
        episodes = 2
        reward = "alive"
        [[steps]]
        name = "train"
        kind = "train"
        preset = "fast"
        history = 2
        [[steps]]
        name = "eval"
        kind = "evaluate"
        policy = "@train"
        delay = 0.2
        """), "r.toml")
    train, ev = recipe.steps
    assert train.settings.seed == 4 and train.settings.env.reward == "alive" and train.settings.env.history == 2
    assert train.settings.preset == "fast" and train.settings.algo == "lqr"  # the preset was applied
    assert ev.settings.seed == 4 and ev.settings.episodes == 2
    # The evaluation uses the trained policy's env (history 2), without its reward shaping, plus the delay.
    assert ev.settings.env.history == 2 and ev.settings.env.reward is None and ev.settings.env.delay == 0.2


RECIPE_ERRORS = {
    "typo-eval-field": ("""
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulum-v5"
        episode = 3
        """, ["'episode'", "episodes"]),
    "typo-lqr-table": ("""
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        lqr = {obs_lag = 3}
        """, ["obs_lag"]),
    "typo-top-level": ("""
        descripton = "x"
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulum-v5"
        """, ["descripton", "description"]),
    "negative-value": ("""
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        timesteps = -3
        """, ["timesteps"]),
    "bad-schedule": ("""
        [[steps]]
        name = "a"
        kind = "train"
        lr = "linear:1"
        """, ["linear:1"]),
    "unknown-preset": ("""
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fats"
        """, ["fats", "fast"]),
    "bad-delay": ("""
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        delay = 0.01
        """, ["0.01"]),
    "bad-env": ("""
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulm-v5"
        """, ["InvertedPendulum-v5"]),
    "bad-reward": ("""
        [[steps]]
        name = "a"
        kind = "train"
        reward = "quadratik"
        """, ["quadratic"]),
    "later-step": ("""
        [[steps]]
        name = "b"
        kind = "evaluate"
        policy = "@a"
        [[steps]]
        name = "a"
        kind = "train"
        preset = "fast"
        """, ["@a"]),
    "reference-to-evaluate-step": ("""
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulum-v5"
        [[steps]]
        name = "b"
        kind = "evaluate"
        policy = "@a"
        """, ["@a"]),
    "unknown-kind": ("""
        [[steps]]
        name = "a"
        kind = "trian"
        """, ["trian"]),
    "duplicate-names": ("""
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulum-v5"
        [[steps]]
        name = "a"
        kind = "evaluate"
        policy = "zero"
        env = "InvertedPendulum-v5"
        """, ["'a'"]),
    "no-steps": ("""
        steps = []
        """, ["steps"]),
    "no-name": ("""
        description = "the recipe's name is missing"
        [[steps]]
        kind = "evaluate"
        policy = "pid"
        env = "InvertedPendulum-v5"
        """, ["'name'"]),
}


@pytest.mark.parametrize("case", sorted(RECIPE_ERRORS))
def test_recipe_validation_errors(case):
    text, fragments = RECIPE_ERRORS[case]
    text = textwrap.dedent(text)
    if case != "no-name":
        text = 'name = "t"\n' + text
    with pytest.raises(MotorlabError) as info:
        parse_recipe(text, f"{case}.toml")
    message = str(info.value)
    assert message.startswith(f"{case}.toml"), message  # names the file
    assert "\n" not in message
    for fragment in fragments:
        assert fragment in message, message


def test_unknown_recipe_name_suggests_close_match():
    with pytest.raises(MotorlabError, match="pendulum"):
        load_recipe("pendulm")


# ---- running a study from the CLI ---------------------------------------------------

STUDY = """
name = "small"
description = "tiny study for the tests"

[defaults]
env = "InvertedPendulum-v5"
seed = 0
episodes = 3
progress = false

[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"

[[steps]]
name = "fast"
kind = "train"
preset = "fast"
timesteps = 2000
until_solved = true

[[steps]]
name = "fast-on-delay"
kind = "evaluate"
policy = "@fast"
delay = 0.2

[[steps]]
name = "ppo"
kind = "train"
algo = "ppo"
timesteps = 256
hyperparams = {n_steps = 128, batch_size = 64}
"""


def check_study_outputs(out, step_names: list[str]) -> dict:
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == step_names
    assert summary["pid.return_mean"] == 1000.0 and summary["pid.success_rate"] == 1.0
    assert isinstance(summary["fast.steps_to_success"], int)
    assert summary["fast.steps_to_success"] == summary["fast.timesteps"] <= 2000
    assert "ppo.steps_to_success" in summary and summary["ppo.steps_to_success"] is None  # not solved
    assert summary["ppo.timesteps"] == 256
    table = (out / "table.txt").read_text().splitlines()
    assert len(table) == 1 + len(step_names)
    for name, line in zip(step_names, table[1:]):
        assert line.startswith(name)
    assert_png(out / "plots" / "returns.png")
    assert_png(out / "plots" / "steps_to_success.png")
    for name in step_names:
        step_summary = read_summary(out / name)
        assert step_summary, name
        assert_png(out / name / "plots" / "observation_trace.png")
    for name in ("fast", "ppo"):
        assert_png(out / name / "plots" / "learning_curve.png")
    return summary


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """The brief's small study, run once from the CLI: evaluate pid; train the fast preset
    until solved; evaluate '@fast' on a 0.2 s delay; a tiny PPO run."""
    folder = tmp_path_factory.mktemp("study")
    path = folder / "small.toml"
    path.write_text(STUDY)
    out = folder / "out"
    proc = run_cli("run", path, "--out", out)
    assert_ok(proc)
    return path, out, proc


STEPS = ["pid", "fast", "fast-on-delay", "ppo"]


def step_mtimes(out) -> dict[str, int]:
    return {name: (out / name / "summary.json").stat().st_mtime_ns for name in STEPS}


def test_study_writes_summary_table_plots_and_step_folders(study):
    _, out, proc = study
    summary = check_study_outputs(out, STEPS)
    assert "already done" not in proc.stdout
    # '@fast' was evaluated from the study's own fast folder, on the delayed env.
    assert "fast-on-delay.return_mean" in summary
    step = read_summary(out / "fast-on-delay")
    assert step["delay"] == 0.2 and step["episodes"] == 3
    policy = tomllib.loads((out / "fast-on-delay" / "config.toml").read_text())["policy"]
    assert Path(policy).resolve() == (out / "fast").resolve()


def test_study_rerun_keeps_finished_steps(study):
    path, out, _ = study
    before = step_mtimes(out)
    proc = run_cli("run", path, "--out", out, "--resume")
    assert_ok(proc)
    assert proc.stdout.count("already done") == len(STEPS)
    assert step_mtimes(out) == before
    check_study_outputs(out, STEPS)


def test_study_rerun_redoes_only_changed_steps(study, tmp_path):
    path, out, _ = study
    before = step_mtimes(out)
    changed = tmp_path / "small.toml"
    changed.write_text(path.read_text().replace('policy = "pid"', 'policy = "pid"\nepisodes = 2'))
    proc = run_cli("run", changed, "--out", out, "--resume")
    assert_ok(proc)
    assert "settings or inputs changed; its earlier run is replaced" in proc.stdout
    after = step_mtimes(out)
    assert after["pid"] != before["pid"]  # its settings changed: run again
    kept = [name for name in STEPS if name != "pid"]
    assert {k: after[k] for k in kept} == {k: before[k] for k in kept}
    assert read_summary(out / "pid")["episodes"] == 2
    assert proc.stdout.count("already done") == len(kept)


def test_the_step_schema_is_a_union_of_the_registered_kinds():
    """The registry builds the recipe schema: every kind once, told apart by `kind`, and every
    step of every bundled recipe is one of them."""
    from motorlab.kinds import KINDS
    from motorlab.recipes import step_union

    union = step_union()
    schema = union.json_schema()
    assert set(schema["discriminator"]["mapping"]) == set(KINDS)
    for name in bundled():
        raw = tomllib.loads(bundled()[name].read_text())
        for step in raw["steps"]:
            parsed = union.validate_python({"kind": "train", **step})
            assert parsed.kind == step.get("kind", "train") and parsed.name == step["name"]
    with pytest.raises(ValueError, match="episodes"):
        union.validate_python({"kind": "evaluate", "name": "e", "policy": "pid", "episodes": 0})


INPUT_RECIPE = """name = "with-input"
[inputs]
sar = "the SAR to train in: a sar.npz"

[[steps]]
name = "ppo"
kind = "train"
env = "InvertedPendulum-v5"
timesteps = 1000

[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"
env = "InvertedPendulum-v5"
episodes = 3
sar = "${sar}"
"""


def test_set_overrides_recipe_fields_one_step_or_every_step():
    recipe = load_recipe("pendulum", {"ppo.timesteps": "5000", "episodes": "3"})
    steps = {s.name: s for s in recipe.steps}
    assert steps["ppo"].settings.timesteps == 5000 and steps["ppo-delay"].settings.timesteps == 50000
    assert all(s.settings.episodes == 3 for s in recipe.steps if "episodes" in type(s.settings).model_fields)


@pytest.mark.parametrize(("given", "fragments"), [
    ({"pp.timesteps": "1"}, ("--set pp.timesteps", "no step 'pp'", "did you mean ppo?")),
    ({"ppo.timestep": "1"}, ("--set ppo.timestep", "step 'ppo'", "no field 'timestep'", "did you mean timesteps")),
    ({"timestep": "1"}, ("--set timestep", "no step", "has a field 'timestep'", "did you mean timesteps")),
])
def test_set_names_the_bad_field_with_close_matches(given, fragments):
    with pytest.raises(MotorlabError) as caught:
        load_recipe("pendulum", given)
    for fragment in fragments:
        assert fragment in str(caught.value)


def test_a_recipe_input_is_required_and_filled_by_set(tmp_path):
    path = tmp_path / "input.toml"
    path.write_text(INPUT_RECIPE)
    with pytest.raises(MotorlabError, match=r"needs --set sar=VALUE: the SAR to train in: a sar.npz"):
        load_recipe(str(path))
    filled = set_fields(tomllib.loads(INPUT_RECIPE), {"sar": "runs/fit/sar.npz"}, str(path))
    assert filled["steps"][1]["sar"] == "runs/fit/sar.npz" and "sar" not in filled["steps"][0]
    with pytest.raises(MotorlabError, match=r"SAR file .*missing\.npz does not exist"):  # filled, then checked
        load_recipe(str(path), {"sar": str(tmp_path / "missing.npz")})


def test_run_set_on_the_command_line_is_one_line_on_a_mistake(tmp_path):
    from tests.helpers import assert_one_line_error

    proc = run_cli("run", "pendulum", "--set", "ppo.timestep=5000", "--check")
    assert_one_line_error(proc, "--set ppo.timestep", "did you mean timesteps")
    proc = run_cli("run", "pendulum", "--set", "ppo.timesteps=5000", "--check")
    assert_ok(proc)


def test_motorlab_recipes_lists_every_bundled_recipe():
    """`motorlab recipes` lists them all, those that need an input (--set sar=...) too, and exits 0."""
    proc = run_cli("recipes")
    assert_ok(proc)
    listed = {line.split(":", 1)[0] for line in proc.stdout.splitlines() if ":" in line}
    assert set(bundled()) <= listed and "sar-hand-published" in listed


# ---- seeds per arm (issue 38): full comparisons on 5 seeds, the rest say they are demos --------

MIN_SEEDS = 5
# The bundled full-size comparisons: every arm on MIN_SEEDS seeds or more, no demo note
FULL = ("sar-hand", "sar-hand-reference", "sar-hand-published", "sar-legs", "sar-legs-reference",
        "sar-legs-published", "sar-ant", "mbrl-cartpole")


def arms(recipe) -> dict[str, int]:
    """The trained arms a recipe's findings rest on, with their number of seeds: its training steps
    that no other training step builds on (play feeds SAR-RL through collect and fit: not an arm)."""
    by_name = {s.name: s for s in recipe.steps}

    def upstream(name: str) -> set[str]:
        return {m for n in by_name[name].inputs() for m in {n, *upstream(n)}}

    feeding = set().union(*(upstream(s.name) for s in recipe.steps if s.kind.trains))
    return {s.name: len(s.seeds or [0]) for s in recipe.steps if s.kind.trains and s.name not in feeding}


@pytest.fixture(scope="module")
def every_recipe(request) -> dict:
    """Every bundled recipe, loaded (the published-SAR ones with MyoSuite's published SARs)."""
    given = {"sar-hand-published": {"sar": str(request.getfixturevalue("hand_sar"))},
             "sar-legs-published": {"sar": str(request.getfixturevalue("legs_sar"))}}
    return {name: load_recipe(name, given.get(name)) for name in sorted(bundled())}


def test_full_comparisons_run_at_least_five_seeds_per_arm(every_recipe):
    for name in FULL:
        recipe = every_recipe[name]
        seeds = arms(recipe)
        assert len(seeds) >= 2 and all(n >= MIN_SEEDS for n in seeds.values()), (name, seeds)
        assert recipe.demo is None, name  # a full study is not excused as a demo
        compared = {n for s in recipe.steps if s.kind.name == "compare" for n in refs_in(s.fields["groups"])}
        assert compared == set(seeds), name  # what it compares is what it trains on 5 seeds
        play = [s for s in recipe.steps if s.name == "play"]
        assert all(s.seeds is None for s in play), name  # play -> collect -> fit stays one run


def test_every_other_recipe_says_its_counts_are_small_on_purpose(every_recipe):
    small = {name for name, recipe in every_recipe.items()
             if name.endswith("-quick") or any(n < MIN_SEEDS for n in arms(recipe).values())}
    assert {"sar-hand-quick", "sar-legs-quick", "sar-ant-quick", "reacher-quick", "mbrl-pendulum", "pendulum",
            "upkie"} <= small
    for name in small:
        assert every_recipe[name].demo, f"{name}: fewer than {MIN_SEEDS} seeds per arm, and no demo line"
    assert not small & set(FULL)


def test_steps_after_a_five_seed_arm_take_every_seed(every_recipe, tmp_path):
    """A dry run of each full recipe's plan (the runner's run folders and resolved references, nothing
    run): zero-shot, evaluate and compare steps take all 5 seeds of each arm, and the zero-shot
    findings (`sar-rl.<env>.success_rate_mean`) are the mean over those 5."""
    from motorlab.evaluation.zeroshot import run_label
    from motorlab.studies.runner import _Outputs, _runs

    for name in FULL:
        recipe = every_recipe[name]
        outputs, seeds = _Outputs(recipe.steps), arms(recipe)
        for step in recipe.steps:
            runs = _runs(step, tmp_path / name, outputs)
            outputs.dirs[step.name] = [d for d, _ in runs]
            settings = runs[0][1]
            if step.kind.name == "compare":
                assert {g: len(paths) for g, paths in settings.groups.items()} == \
                    {g: sum(seeds[n] for n in refs_in(refs)) for g, refs in step.fields["groups"].items()}, name
            if step.kind.name == "evaluate" and step.inputs()[0] in seeds:  # one evaluation per seed
                assert len(runs) == seeds[step.inputs()[0]], (name, step.name)
            if step.kind.name == "zeroshot":
                labels = [run_label(Path(r)) for r in settings.runs]
                assert sorted(labels) == sorted(f"{a}/seed{k}" for a in step.inputs() for k in range(seeds[a]))
                rate = {label: i / 10 for i, label in enumerate(labels)}  # each run's own success rate
                summary = step.kind.summary.model_validate({
                    "runs": labels, "envs": settings.envs, "episodes": 1, "seed": 0, "numerical_faults": 0,
                    **{f"{label}.{env}.{key}": rate[label] for label in labels for env in settings.envs
                       for key in ("success_rate", "return_mean")}})
                headline = step.kind.headline(summary)
                for f in (f for f in recipe.findings if f.step == step.name):
                    per_seed = step.kind.seed_values([(step.name, summary)], f.key)
                    arm = f.key.split(".")[0]
                    assert sorted(per_seed) == sorted((f"seed{k}", rate[f"{arm}/seed{k}"]) for k in range(seeds[arm]))
                    assert headline[f.key] == pytest.approx(sum(v for _, v in per_seed) / seeds[arm]), (name, f.key)


# ---- the user's code a recipe names, found at the door (issue 52) ----------------------------

# One step of each kind that validates as it is (earlier steps give what it reads)
CODE_STEPS = {
    "train": {"env": "InvertedPendulum-v5", "algo": "lqr", "timesteps": 300},
    "evaluate": {"policy": "@t", "env": "InvertedPendulum-v5"},
    "video": {"run": "@t"}, "collect": {"run": "@c0"}, "vaf": {"activations": "@c"}, "fit": {"activations": "@c"},
    "zeroshot": {"runs": ["@t"], "envs": ["InvertedPendulum-v5"]},
    "robustness": {"policies": ["@t"], "vary": ["delay=0,0.1"]}, "compare": {"groups": {"a": ["@t"]}},
    "dynamics-collect": {"env": "InvertedPendulum-v5", "episodes": 2}, "dynamics-fit": {"transitions": "@dc"},
    "dynamics-check": {"model": "@df"}, "mpc": {"env": "InvertedPendulum-v5", "model": "@df"},
    "mbrl": {"env": "InvertedPendulum-v5"},
    "ablate": {"run": "@t"}, "import-emg": {"file": "emg.csv", "rate": 2000.0}, "similarity": {"a": "@f", "b": "@f"},
}
EARLIER = [{"name": "t", "kind": "train", **CODE_STEPS["train"]}, {"name": "c0", "kind": "train", **CODE_STEPS["train"]},
           {"name": "c", "kind": "collect", "run": "@t"}, {"name": "dc", "kind": "dynamics-collect", "env": "Reacher-v5"},
           {"name": "df", "kind": "dynamics-fit", "transitions": "@dc"},
           {"name": "f", "kind": "fit", "activations": "@c", "n_synergies": 2}]


def _code_cases() -> list[tuple[str, str]]:
    from motorlab.kinds import KINDS
    from motorlab.recipes import code_fields

    return [(name, field) for name, k in KINDS.items() for field in sorted(code_fields(k))]


def test_every_kind_has_a_step_that_validates():
    import tomli_w

    from motorlab.kinds import KINDS

    assert set(CODE_STEPS) == set(KINDS)
    steps = EARLIER + [{"name": f"s-{k}", "kind": k, **fields} for k, fields in CODE_STEPS.items()]
    parse_recipe(tomli_w.dumps({"name": "every-kind", "steps": steps}))


def test_the_code_fields_are_found_from_the_marks():
    """The fields checked are found from the settings models (UserCode marks), not listed: mpc's and mbrl's
    reward and termination and zeroshot's envs among them."""
    cases = set(_code_cases())
    assert {("mpc", "termination"), ("mbrl", "termination"), ("mpc", "reward"), ("zeroshot", "envs"),
            ("train", "env"), ("train", "reward")} <= cases



@pytest.mark.parametrize(("kind", "field"), _code_cases())
def test_a_recipe_naming_missing_code_is_refused_at_the_door(kind, field):
    """A recipe naming a module that does not import, or a function (or env id) its module lacks, in any
    field that names the user's code, of any kind, fails validation (`run --check`) in one line naming
    the field and the module, never a late failure when the step runs."""
    import math

    import tomli_w
    from hypothesis import given, settings
    from hypothesis import strategies as st

    modules = st.from_regex(r"nosuch_[a-z]{1,8}", fullmatch=True).map(lambda m: (m, "Thing"))
    names = st.from_regex(r"[a-z][a-z0-9_]{0,10}", fullmatch=True).filter(lambda n: not hasattr(math, n))
    missing = st.one_of(modules, names.map(lambda n: ("math", n)))

    @settings(max_examples=4, deadline=None, derandomize=True, database=None)
    @given(missing=missing)
    def check(missing):
        module, name = missing
        value = f"{module}:{name}-v0" if field in ("env", "envs") else f"{module}:{name}"
        step = {"name": "s", "kind": kind, **CODE_STEPS[kind], field: [value] if field == "envs" else value}
        with pytest.raises(MotorlabError) as e:
            parse_recipe(tomli_w.dumps({"name": "x", "steps": [*EARLIER, step]}))
        text = str(e.value)
        assert "\n" not in text and field in text and module in text, text
        if module == "math":
            assert name in text, text

    check()


@pytest.mark.parametrize(("field", "value", "named"), [
    ("termination", "nosuch_terminations:fell", "nosuch_terminations"),
    ("reward", "math:nosuch_reward", "nosuch_reward"),
])
def test_run_check_finds_an_mpc_recipes_functions(tmp_path, field, value, named):
    """Listed: `run --check` called a recipe valid when its mpc termination module did not exist."""
    from tests.helpers import assert_one_line_error, run_here

    recipe = tmp_path / "mpc.toml"
    recipe.write_text(textwrap.dedent(f"""
        name = "mpc"
        [[steps]]
        name = "dc"
        kind = "dynamics-collect"
        env = "Reacher-v5"
        [[steps]]
        name = "df"
        kind = "dynamics-fit"
        transitions = "@dc"
        [[steps]]
        name = "plan"
        kind = "mpc"
        env = "Reacher-v5"
        model = "@df"
        {field} = "{value}"
    """))
    assert_one_line_error(run_here("run", recipe, "--check", cwd=tmp_path), field, named)


def test_run_check_finds_a_zeroshot_recipes_envs(tmp_path):
    """Listed: `run --check` called a recipe valid when its zeroshot envs' module did not exist."""
    from tests.helpers import assert_one_line_error, run_here

    recipe = tmp_path / "zeroshot.toml"
    recipe.write_text(textwrap.dedent("""
        name = "zeroshot"
        [[steps]]
        name = "t"
        env = "InvertedPendulum-v5"
        algo = "lqr"
        timesteps = 300
        [[steps]]
        name = "z"
        kind = "zeroshot"
        runs = ["@t"]
        envs = ["InvertedPendulum-v5", "nosuch_envs_pkg:Arm-v0"]
    """))
    assert_one_line_error(run_here("run", recipe, "--check", cwd=tmp_path), "envs", "nosuch_envs_pkg")
