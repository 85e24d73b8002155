"""Every command as an object (motorlab.command): what each prints of a result (`report`, on
summaries built by hand), the settings quirks the command line relied on (evaluate's env from
the run folder, zeroshot's env ids among the runs, compare's --group, train's --config and
--resume), the export command's checks, and the recipes listing (every bundled recipe, those
that need --set too). No training, no env stepping: fast."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from rich.console import Console

from motorlab.command import Command, NoFolder
from motorlab.errors import MotorlabError
from motorlab.kinds import KINDS
from motorlab.kinds.dynamics import (
    DYNAMICS_CHECK,
    DYNAMICS_COLLECT,
    DYNAMICS_FIT,
    DynamicsCheckSummary,
    DynamicsCollectSummary,
    DynamicsFitSummary,
)
from motorlab.kinds.evaluate import EVALUATE, ZEROSHOT, EvaluateSummary, ZeroshotSummary
from motorlab.kinds.export import EXPORT, Exported
from motorlab.kinds.media import COMPARE, VIDEO, VideoSummary
from motorlab.kinds.planning import MBRL, MPC, MbrlSummary, MpcSummary
from motorlab.kinds.report import PLOT, REPORT
from motorlab.kinds.robustness import ROBUSTNESS, RobustnessSummary
from motorlab.kinds.synergies import COLLECT, FIT, VAF, CollectSummary, FitSummary, VafSummary
from motorlab.kinds.synergy_files import EXPORT_SKLEARN, IMPORT_SKLEARN
from motorlab.kinds.train import TRAIN, TrainInvocation, TrainSummary
from motorlab.recipe_list import RECIPES
from motorlab.recipes import bundled
from motorlab.settings import Summary

pytestmark = pytest.mark.fast

RUN = Path("runs/x")
COMMANDS: list[Command] = [*KINDS.values(), EXPORT, REPORT, PLOT, IMPORT_SKLEARN, EXPORT_SKLEARN, RECIPES]


def printed(cmd: Command, result, settings) -> str:
    console = Console(file=io.StringIO(), width=300)
    cmd.report(result, settings, console)
    return console.file.getvalue()


def run_folder(path: Path, env: dict) -> Path:
    """A finished run folder as far as reading its settings goes: config.toml and summary.json."""
    import tomli_w

    path.mkdir(parents=True)
    (path / "config.toml").write_text(tomli_w.dumps({"algo": "ppo", "env": env}))
    (path / "summary.json").write_text("{}")
    return path


# ---- every command's shape ---------------------------------------------------------------------

@pytest.mark.parametrize("cmd", COMMANDS, ids=lambda c: c.name)
def test_every_command_describes_itself(cmd):
    first = cmd.help().splitlines()[0]
    assert first.endswith("."), first  # the short help in the command list: one whole sentence
    assert cmd.examples and all(e.startswith(("motorlab ", "MUJOCO_GL=egl motorlab ")) for e in cmd.examples)
    for name in cmd.arguments:  # positional arguments are settings fields, or the flat env id
        assert name in cmd.settings.model_fields or name in getattr(cmd.settings, "aliases", ()), name
    for name in cmd.flags:
        assert name in cmd.settings.model_fields, name


def test_command_words():
    assert [c.command for c in (IMPORT_SKLEARN, EXPORT_SKLEARN, FIT, DYNAMICS_FIT, EXPORT, RECIPES)] == [
        "synergies import-sklearn", "synergies export-sklearn", "synergies fit", "dynamics fit", "export", "recipes"]
    assert EXPORT.out_required and REPORT.invocation is NoFolder and VIDEO.out_help.startswith("Folder for the videos")
    assert TRAIN.invocation is TrainInvocation and TRAIN.flags["hyperparams"] == ("--set",)
    assert FIT.flags["n_synergies"] == ("--n-synergies", "--n")


# ---- what each kind prints --------------------------------------------------------------------

TRAINED = dict(run_dir=RUN, eval_return_mean=1000.0, eval_return_min=1000.0, eval_episodes=10, timesteps=12_345,
               wall_seconds=3.25, steps_to_success=4_000, until_solved=True, resumed_from=None, numerical_faults=0)


def test_train_prints_its_run():
    s = TrainSummary.model_construct(**TRAINED)
    out = printed(TRAIN, s, TRAIN.make(env="InvertedPendulum-v5"))
    assert "done runs/x: return 1000.0 (min 1000) over 10 episodes, 12,345 steps, 3.2 s, steps_to_success 4,000" in out
    unsolved = TrainSummary.model_construct(**{**TRAINED, "steps_to_success": None})
    assert out.replace(", steps_to_success 4,000", ", not solved") == printed(TRAIN, unsolved, TRAIN.make())
    budget = TrainSummary.model_construct(**{**TRAINED, "steps_to_success": None, "until_solved": False})
    assert printed(TRAIN, budget, TRAIN.make()).rstrip().endswith("3.2 s")


def test_train_prints_a_resumed_run():
    s = TrainSummary.model_construct(**{**TRAINED, "resumed_from": 6_000})
    s._resumed = True
    assert "done runs/x: resumed at 6,000 steps; return 1000.0 over 10 episodes, 12,345 steps" in printed(
        TRAIN, s, TRAIN.make())
    worker = TrainSummary.model_construct(**{**TRAINED, "resumed_from": 6_000})  # resumed without TRAIN.execute
    assert "resumed at 6,000 steps" in printed(TRAIN, worker, TRAIN.make())
    fresh = TrainSummary.model_construct(**TRAINED)
    fresh._resumed = True
    assert "no checkpoint yet, started over; return 1000.0" in printed(TRAIN, fresh, TRAIN.make())


def test_faults_are_warned_on_stderr(capsys):
    s = TrainSummary.model_construct(**{**TRAINED, "numerical_faults": 2})
    printed(TRAIN, s, TRAIN.make())
    assert "warning: 2 episodes ended on a numerical fault" in capsys.readouterr().err


def test_evaluate_prints_a_table():
    s = EvaluateSummary.model_construct(run_dir=RUN, episodes=10, return_mean=950.5, return_std=3.0, return_min=940.0,
                                        return_max=1000.0, success_rate=0.9, episode_length_mean=950, falls=1)
    out = printed(EVALUATE, s, EVALUATE.make(policy="pid", env="InvertedPendulum-v5", delay=0.2))
    assert "pid on InvertedPendulum-v5" in out and "950.5 ± 3.0" in out and "90%" in out and "falls" in out
    assert "written: runs/x/summary.json" in out


@pytest.mark.parametrize("cmd, summary, settings, expected", [
    (ZEROSHOT, ZeroshotSummary.model_construct(run_dir=RUN), {"runs": ["a"], "envs": ["b"]},
     ["written: runs/x/summary.json, runs/x/plots/zeroshot.png"]),
    (ROBUSTNESS, RobustnessSummary.model_construct(run_dir=RUN), {"policies": ["pid"], "vary": ["delay=0:0.2:3"]},
     ["written: runs/x/summary.json, curves.csv, plots/robustness.png"]),
    (VIDEO, VideoSummary.model_construct(run_dir=RUN, videos=["v/episode_0.mp4", "v/episode_1.mp4"],
                                         returns=[12.0, 13.5]), {"run": "r"},
     ["written: v/episode_0.mp4  (return 12.0)", "written: v/episode_1.mp4  (return 13.5)"]),
    (COMPARE, Summary(run_dir=RUN), {"groups": {"A": ["a"]}}, ["written: runs/x/plots/learning_curves.png"]),
    (COLLECT, CollectSummary.model_construct(run_dir=RUN, episodes_kept=4, threshold=12.345, samples=2000,
                                             n_signals=39, signal="act"), {"run": "r"},
     ["kept 4 episodes (return >= 12.3), 2,000 samples x 39 muscle activations (act) -> runs/x/activations.npz"]),
    (VAF, VafSummary.model_construct(run_dir=RUN, method="pca", samples=2000, n_muscles=3, vaf=[0.5, 0.85, 1.0],
                                     n_for_threshold=2, threshold=0.8, vaf_definition="centred", cv_folds=0,
                                     vaf_std=[0.0] * 3, muscle_threshold=0.75, n_by_muscle_vaf=3, n_by_elbow=None,
                                     muscle_vaf=[[0.4, 0.6, 0.5], [0.7, 0.9, 0.8], [1.0, 1.0, 1.0]]),
     {"activations": "a.npz"},
     ["VAF (pca, centred, in-sample), 2,000", "85.0% <- total", "100.0% <- muscles",
      "N by total VAF >= 80%: 2; by every muscle's VAF >= 75%: 3; by the elbow: none; written: runs/x/vaf.png"]),
    (FIT, FitSummary.model_construct(run_dir=RUN, n_synergies=5, method="pca-ica", n_muscles=39, vaf=0.8123,
                                     sar="runs/x/sar.npz", chosen_by="given"), {"activations": "a.npz", "n_synergies": 5},
     ["5 synergies (pca-ica) for 39 muscles, VAF 81.2% -> runs/x/sar.npz; N chosen by: given"]),
    (DYNAMICS_COLLECT, DynamicsCollectSummary.model_construct(
        run_dir=RUN, transitions=50_000, state_size=8, action_size=2, transitions_per_second=123456.7,
        simulator="closed-form", numerical_faults=0), {"env": "Reacher-v5"},
     ["50,000 transitions (8 state, 2 action entries) at 123,457/s via closed-form -> runs/x/transitions.npz"]),
    (DYNAMICS_FIT, DynamicsFitSummary.model_construct(run_dir=RUN, valid_mse=0.00123, epochs_run=7,
                                                      wall_seconds=1.25), {"transitions": "t.npz"},
     ["valid_mse 1.23e-03 (normalized) after 7 epochs, 1.2 s -> runs/x/model.json, plots/loss.png"]),
    (DYNAMICS_CHECK, DynamicsCheckSummary.model_construct(
        run_dir=RUN, tip_error_mean_h1=0.0012, tip_error_mean_h5=0.004, state_nrmse_h1=0.1, worst_dimension="qvel0",
        worst_dimension_nrmse=0.25, worst_dimension_horizon=10), {"model": "m"},
     ["open-loop error: h1 1.2 mm, h5 4.0 mm", "worst entry: qvel0 (0.250 after 10 steps); written: "
      "runs/x/error_by_dimension.csv"]),
    (MPC, MpcSummary.model_construct(run_dir=RUN, return_mean=-3.61, return_std=0.5, final_distance_mean=0.0123,
                                     disagreement_mean=None, plan_ms_median=4.2, episodes=5, reward_source="builtin"),
     {"env": "Reacher-v5", "model": "m"},
     ["return -3.61 ± 0.50, final distance 12.3 mm (mean), planning 4.20 ms/step (median) over 5 episodes "
      "(builtin reward) -> runs/x"]),
    (MBRL, MbrlSummary.model_construct(run_dir=RUN, final_return_mean=250.0, resumed_rounds=2, rounds=5,
                                       env_steps=5000, plan_ms_median=2.5), {"env": "InvertedPendulum-v5"},
     ["return 250.00 after 5 rounds, 5,000 env steps (2 rounds were done before); planning 2.5 ms/step -> "
      "runs/x/curve.csv, plots/learning_curve.png"]),
], ids=lambda x: x.name if isinstance(x, Command) else None)
def test_each_kind_prints_what_it_wrote(cmd, summary, settings, expected):
    out = printed(cmd, summary, cmd.settings.model_construct(**settings))
    for line in expected:
        assert line in out, out


def test_the_other_commands_print_what_they_wrote():
    onnx = {"algo": "ppo", "history": 1, "max_abs_error": 2e-7, "checked_observations": 100, "onnx": "d/policy.onnx",
            "sidecar": "d/policy.onnx.json"}
    assert "exported PPO policy to ONNX (history 1, max |onnxruntime - torch| 2e-07 on 100 observations) -> " \
           "d/policy.onnx, d/policy.onnx.json" in printed(EXPORT, Exported("onnx", onnx), None)
    run = printed(EXPORT, Exported("run", {"exported_files": ["a", "b"], "run_dir": "share/ppo"}), None)
    assert "exported 2 files (no pickle) -> share/ppo" in run
    zipped = {"algo": "sac", "num_timesteps": 20000, "observation_normalized": True, "run_dir": "runs/sac"}
    no_env = EXPORT.settings.model_construct(env=None)
    assert "SAC policy (20,000 steps, normalized observations) -> runs/sac/policy.json, policy.safetensors; " \
           "evaluate it with --env ENV_ID" in printed(EXPORT, Exported("zip", zipped), no_env)
    assert printed(REPORT, Path("r/report.html"), None).strip() == "written: r/report.html"
    assert printed(PLOT, [Path("p/a.png"), Path("p/b.png")], None).split() == ["written:", "p/a.png", "written:",
                                                                                "p/b.png"]

    class Sar:
        n_synergies, n_muscles, metadata = 4, 12, {"import_check_max_abs_error": 3e-9}

    out = printed(IMPORT_SKLEARN, Sar(), IMPORT_SKLEARN.make(folder="f", out="sar.npz"))
    assert "4 synergies x 12 muscles -> sar.npz (decode matches scikit-learn, max abs error 3.0e-09)" in out

    class Result:
        n_synergies, n_muscles, max_abs_error = 5, 12, 1e-8

    out = printed(EXPORT_SKLEARN, Result(), EXPORT_SKLEARN.make(sar="s.npz", out="folder"))
    assert "5 synergies x 12 muscles -> folder (MyoSuite's chain matches motorlab's decode" in out


# ---- settings the command line gave by hand before -------------------------------------------

def test_evaluate_acts_in_the_run_folders_env(tmp_path):
    run = run_folder(tmp_path / "ppo", {"id": "Hopper-v5", "delay": 0.1, "history": 3, "reward": "alive",
                                        "kwargs": {"a": 1}})
    s = EVALUATE.make(policy=str(run), delay=0.2, env_kwargs={"b": 2})
    assert (s.env.id, s.env.delay, s.env.history, s.env.reward, s.env.kwargs) == ("Hopper-v5", 0.2, 3, None,
                                                                                  {"a": 1, "b": 2})
    assert EVALUATE.make(policy=str(run), env="Walker2d-v5").env.id == "Walker2d-v5"
    assert EVALUATE.make(policy="pid", env="Reacher-v5").env.id == "Reacher-v5"
    with pytest.raises(MotorlabError, match=r"no env for 'pid': give --env ENV_ID"):
        EVALUATE.make(policy="pid")
    with pytest.raises(MotorlabError, match="neither a run folder nor a built-in controller"):
        EVALUATE.make(policy=str(tmp_path / "nothing"), env="Hopper-v5")
    # a recipe's "@step" is the study's to resolve
    assert EVALUATE.validate({"policy": "@ppo", "env": "Hopper-v5"}).policy == "@ppo"


def test_zeroshot_takes_env_ids_given_among_the_runs(tmp_path):
    run = run_folder(tmp_path / "ppo", {"id": "InvertedPendulum-v5"})
    s = ZEROSHOT.make(runs=[str(run), "InvertedDoublePendulum-v5"], envs=["Hopper-v5,Walker2d-v5"])
    assert s.runs == [str(run)] and s.envs == ["Hopper-v5", "Walker2d-v5", "InvertedDoublePendulum-v5"]
    with pytest.raises(MotorlabError, match=r"give at least one run folder and one env \(--envs ID ...\)\."):
        ZEROSHOT.make(runs=["Hopper-v5"], envs=["Walker2d-v5"])
    with pytest.raises(MotorlabError, match="give at least one run folder and one env"):
        ZEROSHOT.make(runs=[str(run)])


def test_compare_reads_groups_as_the_command_line_writes_them():
    expected = {"SAR-RL": ["runs/a", "runs/b"], "RL-E2E": ["runs/c"]}
    assert COMPARE.make(groups=["SAR-RL=runs/a,runs/b", "RL-E2E=runs/c"]).groups == expected
    assert COMPARE.make(groups={"SAR-RL": "runs/a,runs/b", "RL-E2E": ["runs/c"]}).groups == expected
    for bad in (["SAR-RL"], ["=runs/a"], ["SAR-RL="], {"SAR-RL": ""}):
        with pytest.raises(MotorlabError, match=r"write LABEL=RUN_DIR\[,RUN_DIR\.\.\.\], e\.g\. --group "
                                                r"SAR-RL=runs/a,runs/b\."):
            COMPARE.make(groups=bad)


def test_robustness_takes_env_settings_flat():
    s = ROBUSTNESS.make(policies=["pid"], vary=["push-force=0:40:5"], env="InvertedPendulum-v5", push_body="pole",
                        env_kwargs={"reset_noise_scale": 0.1})
    assert s.config()["env"] == {"id": "InvertedPendulum-v5", "push_body": "pole", "kwargs": {"reset_noise_scale": 0.1}}
    assert s.env.push_body == "pole"  # an EnvConfig, as every env-building kind's


# ---- train: --config, --resume, the env id ------------------------------------------------------

def test_train_needs_an_env_id_or_a_config(tmp_path):
    with pytest.raises(MotorlabError, match=r"give an env id \(motorlab train InvertedPendulum-v5\) or --config"):
        TRAIN.make(TRAIN.how(out=tmp_path / "run"), timesteps=100)
    assert not (tmp_path / "run").exists()
    assert TRAIN.make(timesteps=100).env.id == "InvertedPendulum-v5"  # without a command line: the model's default


def sac_run(path: Path, **fields) -> Path:
    """The config.toml of a SAC run on a goal-conditioned env, every field written out (her = false too)."""
    from motorlab.runs import write_config

    path.mkdir(parents=True)
    write_config(path, TRAIN.make(env="PointMaze_UMaze-v3", algo="sac", timesteps=500, **fields).config())
    return path / "config.toml"


def test_train_config_merges_the_given_fields(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "best.toml").write_text("lr = \"1e-3\"\n")
    config = run_folder(tmp_path / "old", {"id": "Hopper-v5", "delay": 0.1, "history": 4}) / "config.toml"
    merged = TRAIN.make(TRAIN.how(config=config), delay=0.3, seed=7, preset_file="best.toml",
                        hyperparams={"n_steps": 64})
    assert merged.preset_file == str(tmp_path / "best.toml") and merged.lr == "1e-3"  # resolved where it was given
    assert (merged.env.id, merged.env.delay, merged.env.history, merged.seed) == ("Hopper-v5", 0.3, 4, 7)
    assert merged.hyperparams == {"n_steps": 64}
    with pytest.raises(MotorlabError, match="is missing; give the config.toml of a motorlab train run"):
        TRAIN.make(TRAIN.how(config=tmp_path / "none.toml"), seed=1)
    (tmp_path / "bad.toml").write_text("algo = [")
    with pytest.raises(MotorlabError, match="bad.toml is not valid TOML"):
        TRAIN.make(TRAIN.how(config=tmp_path / "bad.toml"))


def test_train_config_is_judged_with_the_flags_laid_over_it(tmp_path):
    """`train --config SAC_RUN --her`: --her is judged with the config's SAC, not the default PPO."""
    config = sac_run(tmp_path / "sac")
    with pytest.raises(MotorlabError, match="--her"):  # alone, --her meets the default algorithm
        TRAIN.make(TRAIN.how(), env="PointMaze_UMaze-v3", her=True)
    s = TRAIN.make(TRAIN.how(config=config), her=True)
    assert (s.algo, s.her, s.env.id, s.timesteps) == ("sac", True, "PointMaze_UMaze-v3", 500)
    with pytest.raises(MotorlabError, match="--her"):  # a flag that does not go with the config is still refused
        TRAIN.make(TRAIN.how(config=config), her=True, algo="ppo")


def test_train_config_flags_win_and_a_bad_one_is_named(tmp_path):
    config = sac_run(tmp_path / "sac", seed=0, delay=0.1)
    s = TRAIN.make(TRAIN.how(config=config), seed=3, history=2)
    assert (s.seed, s.env.history, s.env.delay, s.algo) == (3, 2, 0.1, "sac")  # the flags over the config
    with pytest.raises(MotorlabError, match=r"^--seed -1: Input should be greater than or equal to 0$"):
        TRAIN.make(TRAIN.how(config=config), seed=-1)
    with pytest.raises(MotorlabError, match=r"^--timesteps 0: "):
        TRAIN.make(TRAIN.how(config=config), timesteps=0)


def test_train_config_alone_is_the_run_again(tmp_path):
    config = sac_run(tmp_path / "sac", seed=5, delay=0.1, hyperparams={"learning_starts": 100}, progress=False)
    again = TRAIN.make(TRAIN.how(config=config))
    original = TRAIN.make(env="PointMaze_UMaze-v3", algo="sac", timesteps=500, seed=5, delay=0.1,
                          hyperparams={"learning_starts": 100})
    assert again.config() == original.config() and again.progress  # the progress bar is the flags', never the config's
    assert not TRAIN.make(TRAIN.how(config=config), progress=False).progress


def test_train_resume_refuses_what_it_cannot_do(tmp_path):
    unfinished = tmp_path / "unfinished"
    unfinished.mkdir()
    with pytest.raises(MotorlabError, match="--overwrite replaces it; give one of them"):
        TRAIN.how(resume=unfinished, overwrite=True).mode()
    with pytest.raises(MotorlabError, match="drop the other settings"):
        TRAIN.make(TRAIN.how(resume=unfinished), seed=3)
    with pytest.raises(MotorlabError, match="drop the other settings"):
        TRAIN.make(TRAIN.how(resume=unfinished, out=tmp_path / "x"))
    with pytest.raises(MotorlabError, match="drop the other settings"):
        TRAIN.make(TRAIN.how(resume=unfinished, config=tmp_path / "x.toml"))
    with pytest.raises(MotorlabError, match="is not a training run folder"):
        TRAIN.make(TRAIN.how(resume=unfinished), progress=False)
    finished = run_folder(tmp_path / "finished", {"id": "InvertedPendulum-v5"})
    with pytest.raises(MotorlabError, match="finished already"):
        TRAIN.make(TRAIN.how(resume=finished))


def test_train_resume_takes_the_runs_own_settings(tmp_path):
    run_dir = sac_run(tmp_path / "interrupted", seed=4).parent  # config.toml, no summary.json
    how = TRAIN.how(resume=run_dir)
    s = TRAIN.make(how, progress=False)
    assert (s.algo, s.seed, s.progress) == ("sac", 4, False) and TRAIN.make(how).progress
    with pytest.raises(MotorlabError, match="drop the other settings"):  # settings not made with --resume
        TRAIN.execute(TRAIN.make(env="PointMaze_UMaze-v3", algo="sac", seed=5), how, None, False)


# ---- export's checks, and the recipes listing ---------------------------------------------------

def test_export_refuses_zip_options_where_they_do_not_apply(tmp_path):
    with pytest.raises(MotorlabError, match=r"^--onnx exports a run folder's policy; --trust, --env"):
        EXPORT.make(source=tmp_path, onnx=True, trust=True)
    with pytest.raises(MotorlabError, match="is a run folder: it is exported as it is, without --trust"):
        EXPORT.make(source=tmp_path, env="Hopper-v5")
    assert EXPORT.make(source=tmp_path / "model.zip", trust=True, env="Hopper-v5").trust
    with pytest.raises(MotorlabError, match="give --out"):
        EXPORT.execute(EXPORT.make(source=tmp_path), EXPORT.how(), None, False)


def test_recipes_lists_every_bundled_recipe_even_those_needing_inputs():
    console = Console(file=io.StringIO(), width=400)
    settings = RECIPES.make()
    RECIPES.report(RECIPES.invoke(settings, RECIPES.how(), console), settings, console)
    lines = console.file.getvalue().splitlines()
    assert [line.split(":")[0] for line in lines] == sorted(bundled())
    assert any(line.startswith("sar-hand-published: ") and line.endswith(" steps)") for line in lines)


def test_recipes_lists_kinds_and_the_schema():
    console = Console(file=io.StringIO(), width=400)
    settings = RECIPES.make(kinds=True)
    RECIPES.report(RECIPES.execute(settings, RECIPES.how(), console, False), settings, console)
    out = console.file.getvalue()
    assert all(f"{name}: " in out for name in KINDS) and "timesteps = 100000" in out
    console = Console(file=io.StringIO(), width=40)
    settings = RECIPES.make(json_schema=True)
    RECIPES.report(RECIPES.execute(settings, RECIPES.how(), console, False), settings, console)
    assert "discriminator" in json.loads(console.file.getvalue())


def test_the_command_line_reads_no_field_narrower_than_its_settings():
    """A field whose settings take several scalar types (`--obs-noise 0.05` or `0.05..0.1`) reaches its model as
    the text given; the command line types a value (int, float, a switch) only where the model takes that
    type alone. Judged for every field of every command, so a new field cannot be narrowed by its CLI."""
    import types
    import typing

    from motorlab.commandline import value_kind
    from motorlab.registry import COMMANDS

    def members(annotation):
        if typing.get_origin(annotation) is typing.Annotated:
            return members(typing.get_args(annotation)[0])
        if typing.get_origin(annotation) in (typing.Union, types.UnionType):
            return {m for a in typing.get_args(annotation) for m in members(a)} - {type(None)}
        return {annotation}

    scalar = {"int": int, "float": float, "flag": bool}
    checked = 0
    for cmd in COMMANDS.values():
        for name, info in cmd.settings.model_fields.items():
            kind = value_kind(info.annotation)
            if kind in scalar:
                assert members(info.annotation) == {scalar[kind]}, (cmd.name, name, info.annotation)
            if kind in ("numbers", "many", "pairs"):  # a container: every member is one
                assert all(typing.get_origin(m) in (list, tuple, dict) or m is dict for m in members(info.annotation)), \
                    (cmd.name, name, info.annotation)
            checked += 1
    assert checked > 100
