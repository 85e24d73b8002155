"""`motorlab sweep`: seeds × settings on a local process pool or Ray Tune, resumable, aggregated with rliable."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as settings_
from hypothesis import strategies as st

from motorlab.errors import MotorlabError
from motorlab.stats import aggregate, trial_scores
from motorlab.sweeps.grid import label, labels, parse_grid, settings
from motorlab.sweeps.targets import SWEEPABLE
from tests.helpers import (
    ENV_ID,
    TINY_PPO,
    USER_PACKAGES,
    assert_ok,
    assert_one_line_error,
    assert_png,
    free_port,
    read_summary,
    run_cli,
    run_here,
)

TINY = " ".join(["train", ENV_ID, *TINY_PPO])  # ~3 s a trial
LQR = f"train {ENV_ID} --preset fast --until-solved --timesteps 1500 --solve-episodes 2"  # ~1 s a trial
GRID = ["--grid", "lr=3e-4,1e-3"]
LR3, LR1 = label({"lr": "3e-4"}), label({"lr": "1e-3"})  # the settings' folders: slug and hash, lr=3e-4-<hash>


def _run_folders(sweep: Path) -> set[str]:
    return {p.parent.relative_to(sweep).as_posix() for p in sweep.glob("*/seed*/summary.json")}


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory) -> Path:
    """2 seeds × 2 learning rates of a tiny PPO run, on the local pool."""
    out = tmp_path_factory.mktemp("sweep") / "local"
    proc = run_cli("sweep", TINY, "--seeds", "2", *GRID, "--out", out)
    assert_ok(proc)
    assert "across seeds" in proc.stdout and str(out) in proc.stdout
    return out


def test_local_sweep_writes_one_run_folder_per_trial(local_sweep):
    assert _run_folders(local_sweep) == {f"{LR3}/seed0", f"{LR3}/seed1", f"{LR1}/seed0", f"{LR1}/seed1"}
    assert LR3.startswith("lr=3e-4-") and LR1.startswith("lr=1e-3-")  # readable, then the hash of the values
    for run in local_sweep.glob("*/seed*"):
        config = (run / "config.toml").read_text()
        assert f"seed = {run.name.removeprefix('seed')}" in config  # the sweep set --seed
        assert f'lr = "{run.parent.name.removeprefix("lr=").rpartition("-")[0]}"' in config  # ... and the grid's
        assert (local_sweep / "logs" / f"{run.parent.name}-{run.name}.log").is_file()


def test_local_sweep_aggregates_with_rliable(local_sweep):
    summary = read_summary(local_sweep)
    details = json.loads((local_sweep / "aggregate.json").read_text())
    assert summary["trials"] == summary["finished"] == 4 and summary["failed"] == 0
    for setting in (LR3, LR1):
        per_seed = [read_summary(local_sweep / setting / f"seed{s}")["eval_return_mean"] for s in (0, 1)]
        entry = details["metrics"]["final_return"][setting]
        assert entry["values"] == pytest.approx(per_seed)
        # two seeds: their mean, named so; no IQM (it would trim nothing) and no CI (a bootstrap of two
        # seeds is only their range): their range, named as such, in the details
        assert summary[f"{setting}.final_return_mean"] == pytest.approx(np.mean(per_seed))
        assert not any(k.startswith(f"{setting}.") and ("_iqm" in k or "_ci_" in k) for k in summary), summary
        assert entry["statistic"] == "mean" and entry["ci"] is None
        assert entry["range"] == pytest.approx([min(per_seed), max(per_seed)])
        assert entry["method"] == ("range of 2 seeds, not a confidence interval: one needs 5 seeds"
                                   if per_seed[0] != per_seed[1] else "the 2 seeds agree; no confidence interval "
                                   "below 5 seeds")
        assert summary[f"{setting}.seeds"] == 2
        assert 0 <= summary[f"{setting}.success_rate_mean"] <= 1
        # 256 steps never solve it: both censored at the budget, never a value, and no median
        assert summary[f"{setting}.steps_to_success_unsolved"] == 2
        assert summary[f"{setting}.steps_to_success_solved"] == 0
        assert summary[f"{setting}.steps_to_success_median"] is None
        steps = details["metrics"]["steps_to_success"][setting]
        assert steps["text"] == ("0 of 2 seeds, 95% Wilson interval [0%, 66%]; median > 256 (budget), no interval "
                                 "(n = 2: too few seeds for a confidence interval, which needs 5)")
        assert steps["solved_ci"][0] == 0.0 and steps["median_ci"] is None
    p = summary[f"{LR3}.final_return_p_better_than[{LR1}]"]
    a = details["metrics"]["final_return"][LR3]["values"]
    b = details["metrics"]["final_return"][LR1]["values"]
    assert p == pytest.approx(np.mean([(x > y) + 0.5 * (x == y) for x in a for y in b]))
    pair = details["probability_of_improvement"]["final_return"][0]
    assert pair["ci"] is None and "too few" in pair["method"]  # 2 seeds a side: no interval
    assert set(details["profiles"]) == {"final_return", "success_rate"}
    fractions = details["profiles"]["final_return"][LR3]["fraction"]
    assert fractions[0] == 1.0 and fractions[-1] == 0.0 and all(np.diff(fractions) <= 0)
    for name in ("iqm.png", "improvement.png", "profiles.png"):
        assert_png(local_sweep / "plots" / name)
    assert LR3 in (local_sweep / "table.txt").read_text()
    table = (local_sweep / "table.txt").read_text()
    assert "mean " in table and ("range of 2 seeds, not a confidence interval" in table or "seeds agree" in table)
    html = (local_sweep / "report.html").read_text()
    assert f'data-key="{LR3}.final_return_mean"' in html


def test_interrupted_sweep_resumes_without_rerunning_finished_trials(tmp_path):
    out = tmp_path / "resume"
    args = [sys.executable, "-m", "motorlab", "sweep", LQR, "--seeds", "3", "--max-parallel", "1", "--out", str(out)]
    # A new process group to interrupt as Ctrl-C would, with Python's SIGINT handling even when
    # the test runner itself was started with SIGINT ignored (as background jobs are).
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    first = out / "default" / "seed0" / "sweep_trial.toml"
    deadline = time.monotonic() + 120
    while not first.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert first.exists(), proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, (stdout, stderr)
    assert "run the same command again to resume" in stdout, (stdout, stderr)
    assert "interrupted" in stderr and "Traceback" not in stderr + stdout
    assert not (out / "summary.json").exists()
    finished = sorted(p.parent.name for p in out.glob("default/seed*/sweep_trial.toml"))
    assert "seed2" not in finished
    stamp = {s: (out / "default" / s / "summary.json").stat().st_mtime_ns for s in finished}

    again = run_cli("sweep", LQR, "--seeds", "3", "--max-parallel", "1", "--out", out)
    assert_ok(again)
    assert f"{len(finished)} already finished, kept" in again.stdout
    for s, mtime in stamp.items():
        assert (out / "default" / s / "summary.json").stat().st_mtime_ns == mtime  # not run again
    assert read_summary(out)["finished"] == 3


@pytest.mark.parametrize("grid, fragment", [
    ("lr", "write KEY=VALUE1,VALUE2"),
    ("=1,2", "write KEY=VALUE1,VALUE2"),
    ("lr=", "empty value"),
    ("lr=1e-3,,3e-4", "empty value"),
    ("lr=1e-3,1e-3", "repeated"),
    ("lrr=1e-3,3e-4", "has no option --lrr"),
])
def test_bad_grid_gives_one_clear_line_and_writes_nothing(tmp_path, grid, fragment):
    out = tmp_path / "bad"
    assert_one_line_error(run_here("sweep", TINY, "--grid", grid, "--out", out), fragment)
    assert not out.exists()


def test_grid_key_given_twice_is_refused():
    with pytest.raises(MotorlabError, match="given twice"):
        parse_grid(["lr=1,2", "lr=3"])


@pytest.mark.parametrize("target, fragment", [
    (f"train {ENV_ID} --seed 3", "sets --seed of every trial itself"),
    ("plot runs/x", "the sweep target 'plot runs/x' is no recipe or command"),
    (f"train {ENV_ID} --timesteps many", "--timesteps"),
    ("no-such-recipe", "the sweep target 'no-such-recipe' is no recipe or command"),
])
def test_bad_target_gives_one_clear_line(tmp_path, target, fragment):
    out = tmp_path / "bad"
    assert_one_line_error(run_here("sweep", target, "--out", out), fragment)
    assert not out.exists()


def test_unreachable_ray_cluster_fails_fast(tmp_path):
    t0 = time.monotonic()
    proc = run_cli("sweep", TINY, "--backend", "ray", "--address", f"127.0.0.1:{free_port()}", "--out", tmp_path / "x")
    assert_one_line_error(proc, "no Ray cluster answers")
    assert time.monotonic() - t0 < 60 and not (tmp_path / "x").exists()
    assert_one_line_error(run_cli("sweep", TINY, "--address", "h:1"), "add --backend ray")


def test_grid_settings_are_every_combination():
    grid = parse_grid(["lr=1e-3,3e-4", "n_envs=1,2", "lr_sched=linear:1e-3,0|3e-4"])
    assert grid["lr_sched"] == ["linear:1e-3,0", "3e-4"]  # "|" separates values that hold commas
    combos = settings(grid)
    assert len(combos) == 8 and len({label(c) for c in combos}) == 8
    assert label({}) == "default" and "/" not in label({"sar": "runs/fit/sar.npz"})


def test_switch_options_take_true_or_false(tmp_path):
    from motorlab.sweeps.targets import parse_target
    from motorlab.sweeps.trials import command_trials

    target = parse_target(f"train {ENV_ID}")
    trials = command_trials(target, settings(parse_grid(["normalize=true,false"])), [0], tmp_path, {})
    assert trials[0]["job"]["settings"]["normalize"] is True and trials[1]["job"]["settings"]["normalize"] is False
    with pytest.raises(MotorlabError, match="is a switch"):
        command_trials(parse_target(f"train {ENV_ID}"), settings(parse_grid(["normalize=maybe"])), [0], tmp_path, {})


def test_stats_iqm_improvement_and_direction(monkeypatch):
    monkeypatch.setattr("motorlab.stats.REPS", 200)  # bootstrap resamples: what is checked holds for any number
    runs = {"a": [{"final_return": (float(v), False), "steps_to_success": (s, False)}
                  for v, s in zip(range(1, 9), [100] * 8)],
            "b": [{"final_return": (float(v), False), "steps_to_success": (s, c)}
                  for v, s, c in zip(range(-8, 0), [500] * 8, [True] * 4 + [False] * 4)]}
    flat, details = aggregate(runs)
    assert flat["a.final_return_iqm"] == pytest.approx(4.5)  # mean of the middle half: 3, 4, 5, 6
    assert flat["a.final_return_iqm_ci_low"] <= 4.5 <= flat["a.final_return_iqm_ci_high"]
    assert flat["a.final_return_mean"] == pytest.approx(4.5)
    assert flat["a.final_return_p_better_than[b]"] == 1.0
    pair = details["probability_of_improvement"]["final_return"][0]
    # every a above every b: each resample gives P = 1, and a point is shown as no interval
    assert pair["p"] == 1.0 and pair["ci"] is None and "do not overlap" in pair["method"]
    mixed = aggregate({"a": [{"final_return": (float(v), False)} for v in (1, 3, 5, 7, 9)],
                       "b": [{"final_return": (float(v), False)} for v in (2, 4, 6, 8, 10)]})[1]
    pair = mixed["probability_of_improvement"]["final_return"][0]
    assert pair["ci"][0] < pair["p"] < pair["ci"][1] and "over 5 and 5 seeds" in pair["method"]
    few = aggregate({"a": [{"final_return": (float(v), False)} for v in (1, 3, 5, 7)],
                     "b": [{"final_return": (float(v), False)} for v in (2, 4, 6, 8)]})[1]
    assert few["probability_of_improvement"]["final_return"][0]["ci"] is None  # 4 a side: no CI
    tied = aggregate({"a": [{"final_return": (0.0, False)}] * 5, "b": [{"final_return": (0.0, False)}] * 5})[1]
    pair = tied["probability_of_improvement"]["final_return"][0]
    assert pair["p"] == 0.5 and pair["method"].startswith("all tied") and "overlap" not in pair["method"]
    assert flat["a.steps_to_success_p_better_than[b]"] == 1.0  # fewer steps is better
    # steps: 4 of b's 8 seeds censored at 500; the median is Kaplan-Meier's, never a mean of budgets
    assert flat["b.steps_to_success_unsolved"] == 4 and flat["b.steps_to_success_solved"] == 4
    assert flat["b.steps_to_success_median"] == 500.0  # half solved at 500: the KM CDF reaches 0.5 there
    assert flat["a.steps_to_success_median"] == 100.0
    # the median's bootstrap interval (8 seeds): b's median is censored in over a third of the resamples
    b_ci = details["metrics"]["steps_to_success"]["b"]["median_ci"]
    assert b_ci["high"] is None and b_ci["high_above_budget"] and b_ci["above"] == 500
    assert details["metrics"]["steps_to_success"]["a"]["median_ci"]["low"] == 100.0
    assert not any(k.startswith(("a.steps_to_success_", "b.steps_to_success_")) and k.endswith(("_iqm", "_mean"))
                   for k in flat)
    assert aggregate(runs)[0] == flat  # a fixed bootstrap state: the same numbers every time
    assert details["metrics"]["final_return"]["b"]["values"] == list(range(-8, 0))


def test_trial_scores_of_run_and_study():
    run = {"eval_return_mean": 10.0, "eval_success_rate": 0.5, "steps_to_success": None, "timesteps": 256}
    assert trial_scores(run) == {"final_return": (10.0, False), "success_rate": (0.5, False),
                                 "steps_to_success": (256.0, True)}
    study = {"recipe": "r", "steps": ["ppo", "pid"], "ppo.return_mean": 5.0, "ppo.steps_to_success": 100,
             "pid.return_mean": 7.0, "pid.success_rate": 1.0}
    assert trial_scores(study) == {"ppo.final_return": (5.0, False), "ppo.steps_to_success": (100.0, False),
                                   "pid.final_return": (7.0, False), "pid.success_rate": (1.0, False)}


RECIPE = f"""
name = "tiny"
seeds = 3
[defaults]
env = "{ENV_ID}"
[[steps]]
name = "fast"
kind = "train"
preset = "fast"
timesteps = 300  # LQR refits (and evaluates) every 100 steps; it balances after the first
solve_episodes = 2  # LQR evaluates after each update; 10 episodes of 1000 steps each time were most of a trial
[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"
episodes = 2
"""


def test_recipe_sweep_runs_whole_studies_with_the_setting_applied(tmp_path):
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(RECIPE)
    out = tmp_path / "sweep"
    assert_ok(run_cli("sweep", recipe, "--seeds", "2", "--grid", "fast.timesteps=200,300", "--out", out))
    t200, t300 = (label({"fast.timesteps": t}) for t in ("200", "300"))
    assert _run_folders(out) == {f"{t}/seed{s}" for t in (t200, t300) for s in (0, 1)}
    study = out / t200 / "seed1"
    assert (study / "report.html").is_file() and (study / "fast" / "config.toml").is_file()
    config = (study / "fast" / "config.toml").read_text()
    assert "timesteps = 200" in config and "seed = 1" in config  # one seed per trial, not the recipe's 3
    summary = read_summary(out)
    assert summary[f"{t200}.fast.final_return_mean"] == pytest.approx(
        np.mean([read_summary(out / t200 / f"seed{s}")["fast.return_mean"] for s in (0, 1)]))
    assert f"{t300}.pid.final_return_mean" in summary
    assert sorted(p.name for p in (out / "recipes").iterdir()) == sorted(f"{t}-seed{s}.toml" for t in (t200, t300)
                                                                         for s in (0, 1))

    assert_one_line_error(run_here("sweep", recipe, "--grid", "nope.timesteps=1,2", "--out", tmp_path / "x"),
                          "has no step 'nope'")
    assert_one_line_error(run_here("sweep", recipe, "--grid", "pid.timesteps=1,2", "--out", tmp_path / "x"),
                          "has no field 'timesteps'")


def test_study_with_seeds_trains_them_in_parallel_and_evaluates_each(tmp_path):
    recipe = tmp_path / "tiny.toml"
    recipe.write_text(RECIPE.replace('name = "pid"', 'name = "on-delay"')
                      .replace('policy = "pid"', 'policy = "@fast"\ndelay = 0.2'))
    out = tmp_path / "study"
    proc = run_cli("run", recipe, "--out", out)
    assert_ok(proc)
    assert "3 seeds in parallel" in proc.stdout
    assert sorted(p.parent.name for p in (out / "fast").glob("seed*/summary.json")) == ["seed0", "seed1", "seed2"]
    evals = out / "on-delay"
    assert sorted(p.parent.name for p in evals.glob("seed*/summary.json")) == ["seed0", "seed1", "seed2"]
    for s in range(3):  # each seed's policy, evaluated on the delayed env
        assert read_summary(evals / f"seed{s}")["delay"] == 0.2
        assert f"fast/seed{s}" in read_summary(evals / f"seed{s}")["policy"]
    summary = read_summary(out)
    returns = [read_summary(evals / f"seed{s}")["return_mean"] for s in range(3)]
    assert summary["on-delay.seeds"] == 3 and summary["on-delay.return_mean"] == pytest.approx(np.mean(returns))
    # 3 seeds: no IQM (it would be the mean) and no 95% CI (a bootstrap of 3 seeds is about their range)
    assert not any(k.startswith("on-delay.return_") and "_ci_" in k for k in summary), summary
    assert summary["fast.seeds"] == 3 and "fast.return_iqm" not in summary and "on-delay.return_iqm" not in summary

    again = run_cli("run", recipe, "--out", out, "--resume")  # resumes: every seed kept
    assert_ok(again)
    assert again.stdout.count("already done with these settings; kept") == 6


def test_train_config_repeats_a_run(ppo_run, tmp_path):
    out = tmp_path / "again"
    assert_ok(run_cli("train", "--config", ppo_run / "config.toml", "--no-progress", "--out", out))
    first, second = read_summary(ppo_run), read_summary(out)
    assert second["eval_return_mean"] == first["eval_return_mean"]  # same settings and seed: same numbers
    assert (out / "config.toml").read_text() == (ppo_run / "config.toml").read_text()
    assert_one_line_error(run_here("train", "--config", tmp_path / "none.toml"), "none.toml is missing")


def test_interrupted_training_trial_resumes_from_its_checkpoint(tmp_path):
    """A trial interrupted mid-training is continued with `train --resume` by the next run of the
    same sweep: only the rest of its budget is trained, to the same total."""
    out = tmp_path / "sweep"
    target = ("train InvertedPendulum-v5 --algo ppo --timesteps 4096 --checkpoint-every 1024 "
              "--set n_steps=512 --set batch_size=128 --solve-episodes 2")
    args = [sys.executable, "-m", "motorlab", "sweep", target, "--seeds", "1", "--out", str(out)]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    latest = out / "default" / "seed0" / "checkpoint" / "latest.json"
    deadline = time.monotonic() + 120
    while not latest.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    assert latest.exists(), proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, (stdout, stderr)
    run = out / "default" / "seed0"
    assert not (run / "summary.json").exists()

    assert_ok(run_cli("sweep", target, "--seeds", "1", "--out", out))
    summary = read_summary(run)
    assert summary["resumed_from"] >= 1024 and summary["timesteps"] == 4096
    assert (run / "sweep_trial.toml").is_file()
    assert "resumed at" in (out / "logs" / "default-seed0.log").read_text()


# last in this file: test_tune_ray.py's first test uses the same Ray head (conftest.ray_address)
def test_ray_backend_gives_the_same_folders_and_aggregate(local_sweep, ray_address, tmp_path):
    out = tmp_path / "ray"
    proc = run_cli("sweep", TINY, "--seeds", "2", *GRID, "--backend", "ray", "--address", ray_address, "--out", out)
    assert_ok(proc)
    # a user's env registered by their module, named with --import only: the workers' trial
    # processes learn the module from the sweep (one Ray cluster for both: starting two is slow)
    user = run_cli("--import", "userpkg.arm", "sweep", "train ArmReachHeavy-v0 " + " ".join(TINY_PPO),
                   "--seeds", "1", "--backend", "ray", "--address", ray_address,
                   "--out", tmp_path / "user", env={"PYTHONPATH": USER_PACKAGES})
    assert_ok(user)
    assert _run_folders(out) == _run_folders(local_sweep)
    assert (out / "ray").is_dir()  # Ray Tune ran the trials
    ray_summary, local_summary = read_summary(out), read_summary(local_sweep)
    keys = [k for k in local_summary if k.startswith("lr=")]
    assert keys and {k: ray_summary[k] for k in keys} == pytest.approx({k: local_summary[k] for k in keys})
    trained = [json.loads(p.read_text()) for p in (tmp_path / "user").rglob("summary.json")]
    assert [(s["env_id"], s["timesteps"]) for s in trained if "algo" in s] == [("ArmReachHeavy-v0", 256)]


# ---- trial folders unique by construction; a target's own options applied or refused (issue 52) ----------

VALUES = st.one_of(st.text(max_size=80), st.sampled_from(["1e-3", "0.001", "1E-3", "a b", "a_b", "a/b", "a\\b", "é",
                                                          "e", "x" * 300, "http://u:pw@h/db", "http://u:PW@h/db"]),
                   st.floats(allow_nan=False).map(repr))
SETTINGS = st.dictionaries(st.sampled_from(["lr", "n_envs", "set.gamma", "fast.timesteps", "--delay"]), VALUES,
                           min_size=1, max_size=3)


@settings_(max_examples=300, deadline=None, derandomize=True, database=None)
@given(st.lists(SETTINGS, min_size=1, max_size=6, unique_by=lambda d: json.dumps(list(d.items()))))
def test_trial_folders_are_distinct_for_distinct_settings_and_equal_for_equal_ones(combos):
    names = labels(combos)
    assert len(set(names)) == len(combos)  # distinct values: distinct folders
    assert labels([dict(c) for c in combos]) == names  # equal values, the same folders: --resume finds its trials
    assert [label(c) for c in combos] == names  # lengthened only where a sweep's short hashes would collide
    for name in names:
        assert "/" not in name and "\\" not in name and " " not in name and name not in (".", "..")
        assert len(name.encode()) < 100  # one path element, however long the value
        assert ":pw_h" not in name and ":PW_h" not in name  # a password is masked before it makes a name
    assert label({}) == "default"
    with pytest.raises(MotorlabError, match="given twice"):
        labels([combos[0], dict(combos[0])])


def test_values_that_slugify_alike_get_their_own_folders(tmp_path):
    from motorlab.sweeps.targets import parse_target
    from motorlab.sweeps.trials import command_trials

    combos = settings(parse_grid(["set.note=a b|a_b|a/b|http://u:s3cretpw@h/x"]))
    trials = command_trials(parse_target(f"train {ENV_ID} --algo lqr"), combos, [0, 1], tmp_path, {})
    dirs = [t["run_dir"] for t in trials]
    assert len(set(dirs)) == len(dirs) == 8 and len({t["log"] for t in trials}) == 8
    assert all(Path(d).parent.parent == tmp_path.resolve() for d in dirs)  # no "/" of a value makes a folder
    assert not any("s3cretpw" in d for d in dirs)


# what each sweepable command needs on its command line, and a value a user could give each invocation option
ARGS = {"train": ENV_ID, "evaluate": "pid", "video": "r", "synergies collect": "r", "synergies fit": "a.npz",
        "zeroshot": "r --envs E-v0", "robustness": "pid --vary delay=0,0.1", "dynamics collect": ENV_ID,
        "dynamics fit": "t.npz", "dynamics check": "m", "mpc": f"{ENV_ID} --model m", "mbrl": ENV_ID,
        "synergies ablate": "r", "synergies compare": "a b"}
OPTION_WORDS = {"out": ["--out", "elsewhere"], "overwrite": ["--overwrite"], "track": ["--track", "mlflow"],
                "config": ["--config", "CONFIG"], "resume": ["--resume", "r"]}


@pytest.fixture(scope="module")
def lqr_config(tmp_path_factory) -> Path:
    """A train run's config.toml (what --config reads), as `motorlab train --algo lqr --timesteps 300` writes it."""
    path = tmp_path_factory.mktemp("config") / "config.toml"
    path.write_text(f'algo = "lqr"\ntimesteps = 300\nseed = 0\n[env]\nid = "{ENV_ID}"\n')
    return path


@settings_(max_examples=120, deadline=None, derandomize=True, database=None)
@given(command=st.sampled_from(SWEEPABLE), owner=st.sampled_from(["sweep", "tune"]), data=st.data())
def test_every_invocation_option_of_a_target_is_applied_or_refused(lqr_config, command, owner, data):
    """Any set of a command's invocation options, in any order, in a sweep or tune target: each one applied
    (--track, --config) or the target refused in one line naming an option given and where it goes."""
    from motorlab.kinds import for_command
    from motorlab.sweeps.targets import APPLIED, parse_target

    options = data.draw(st.lists(st.sampled_from(list(for_command(command).invocation.model_fields)), unique=True))
    words = [w.replace("CONFIG", str(lqr_config)) for o in options for w in OPTION_WORDS.get(o, [f"--{o}", "x"])]
    assert set(OPTION_WORDS) >= set(for_command(command).invocation.model_fields)  # a new option: give it a value
    try:
        target = parse_target(" ".join([command, ARGS[command], *words]), owner)
    except MotorlabError as e:
        line = str(e)
        refused = [o for o in options if o not in APPLIED]
        assert refused and "\n" not in line and any(f"--{o}" in line for o in refused), line
        assert f"motorlab {owner}" in line or f"the {owner} sets" in line, line
        return
    assert set(options) <= set(APPLIED)  # nothing given was dropped: each is in the target
    assert target.track == (("mlflow",) if "track" in options else ())
    if "config" in options:  # that run's settings, under the given ones
        assert target.given.fields["timesteps"] == 300 and target.given.fields["algo"] == "lqr"


@pytest.mark.parametrize("words, fragment", [
    ("--out elsewhere", "sets --out of every trial itself"),
    ("--overwrite", "--overwrite inside a {owner} target is not applied per trial; give it to the {owner}"),
    ("--resume runs/x", "--resume inside a {owner} target is not applied per trial"),
    ("--seed 2", "sets --seed of every trial itself"),
])
@pytest.mark.parametrize("owner", ["sweep", "tune"])
def test_a_targets_refused_option_is_one_line_before_anything_is_written(tmp_path, words, fragment, owner):
    out = tmp_path / "out"
    extra = ["--space", "lr=loguniform:1e-4,1e-3"] if owner == "tune" else []
    proc = run_here(owner, f"{LQR} {words}", *extra, "--out", out)
    assert_one_line_error(proc, fragment.format(owner=owner))
    assert not out.exists()


@pytest.mark.parametrize("owner", ["sweep", "tune"])
def test_a_targets_unreachable_tracker_is_one_line_without_its_password(tmp_path, owner):
    out = tmp_path / "out"
    extra = ["--space", "lr=loguniform:1e-4,1e-3"] if owner == "tune" else []
    proc = run_here(owner, f"{LQR} --track mlflow=http://me:s3cretpw@127.0.0.1:{free_port()}", *extra, "--out", out)
    line = assert_one_line_error(proc, "no MLflow tracking server answers", "me:***@127.0.0.1")
    assert "s3cretpw" not in line and not out.exists()


def test_a_sweep_records_no_credential_of_its_target_or_grid(tmp_path):
    """A credential in the target is in no file and no folder name the sweep writes (the job files excepted:
    the trial's process needs its settings as given); two grid values that slugify alike run apart."""
    out = tmp_path / "sweep"
    target = f"train {ENV_ID} --algo lqr --timesteps 300 --solve-episodes 1 --set note=postgresql://me:s3cretpw@db/x"
    proc = run_cli("sweep", target, "--seeds", "1", "--grid", "set.tag=a b|a_b", "--out", out)
    assert_ok(proc)
    assert len(list(out.glob("set.tag=a_b-*/seed0/summary.json"))) == 2  # they slugify alike: a folder each
    for path in out.rglob("*"):
        assert "s3cretpw" not in str(path)
        if path.is_file() and not path.name.endswith(".job.json"):
            data = path.read_bytes()
            assert b"s3cretpw" not in data, path
    assert "me:***@db" in (out / "config.toml").read_text()
    again = run_cli("sweep", target, "--seeds", "1", "--grid", "set.tag=a b|a_b", "--out", out, "--resume")
    assert_ok(again)  # the trials are found again by their folders and masked records: none runs twice
    assert "2 already finished, kept" in again.stdout
