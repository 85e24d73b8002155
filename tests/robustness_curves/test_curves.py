"""`motorlab robustness`: policies across a grid of disturbances, as curves with bands over
episodes and seeds; the grid's parsing and its one-line errors."""

from __future__ import annotations

import csv

import pytest

from motorlab.errors import MotorlabError
from motorlab.robustness_curves.curves import subjects
from motorlab.robustness_curves.grid import parse_axis
from tests.helpers import (
    ENV_ID,
    TINY_PPO,
    assert_ok,
    assert_one_line_error,
    assert_png,
    read_summary,
    run_cli,
    run_here,
)


def test_grids_are_linspaces_or_lists():
    assert parse_axis("delay=0:0.3:7").values == pytest.approx((0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3))
    assert parse_axis("obs-noise=0.02,0,0.01").values == (0.0, 0.01, 0.02)  # sorted
    axis = parse_axis("latency=0:4:5")
    assert axis.key == "latency" and axis.env_value(0) is None and axis.env_value(3) == 3


@pytest.mark.parametrize("spec, fragment", [
    ("dealy=0:0.3:7", "did you mean delay"),
    ("delay", "KEY=START:STOP:N"),
    ("delay=0:0.3:1", "N >= 2"),
    ("latency=0:1:3", "whole steps"),
    ("obs-noise=-0.1,0.1", "zero or more"),
])
def test_bad_grids_name_the_problem(spec, fragment):
    with pytest.raises(MotorlabError, match=fragment):
        parse_axis(spec)


@pytest.fixture(scope="module")
def ppo_seeds(tmp_path_factory):
    """One step trained with two seeds (<step>/seed0, seed1), with observation noise and history."""
    root = tmp_path_factory.mktemp("robust") / "ppo"
    for seed in (0, 1):
        assert_ok(run_cli("train", ENV_ID, *TINY_PPO, "--seed", seed, "--history", "2", "--obs-noise", "0.05",
                          "--no-progress", "--out", root / f"seed{seed}"))
    return root


def test_pid_holds_less_as_the_delay_grows(tmp_path, ppo_seeds):
    out = tmp_path / "rob"
    proc = run_cli("robustness", "pid", ppo_seeds / "seed0", ppo_seeds / "seed1", "--vary", "delay=0,0.1,0.3",
                   "--vary", "obs-noise=0,0.05", "--episodes", "3", "--out", out)
    assert_ok(proc)
    s = read_summary(out)
    assert s["policies"] == ["pid", "ppo/seed0", "ppo/seed1"] and s["measure"] == "success"
    assert s["vary"] == {"delay": [0.0, 0.1, 0.3], "obs_noise": [0.0, 0.05]}
    pid = s["curves"]["pid"]["delay"]
    # PID balances without delay and falls under 0.3 s: the grid's ends only
    assert pid["return_mean"][0] == 1000 and pid["return_mean"][-1] < 200
    assert pid["success_rate"][0] == 1 and pid["success_rate"][-1] == 0
    assert s["pid.delay.holds_from"] == 0 and s["pid.delay.holds_to"] in (0.0, 0.1)
    ppo = s["curves"]["ppo"]["delay"]  # the two seeds are one curve
    assert ppo["seeds"] == 2 and len(ppo["return_mean"]) == 3
    with open(out / "curves.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 3 * (3 + 2) * 3  # policies x grid values x episodes
    assert {r["run"] for r in rows if r["policy"] == "ppo"} == {"ppo/seed0", "ppo/seed1"}
    assert_png(out / "plots" / "robustness.png")
    assert "holds over" in proc.stdout
    assert s["numerical_faults"] == 0


def test_runs_keep_their_structure_but_not_their_training_disturbances(ppo_seeds):
    (run,) = subjects([str(ppo_seeds / "seed0")], {"push_body": "pole"})
    assert run.env.history == 2 and run.env.push_body == "pole"
    assert run.env.obs_noise is None  # trained with noise; tested on the grid's own
    (pid,) = subjects(["pid"], {"id": ENV_ID})
    assert pid.env.id == ENV_ID


def test_the_env_is_an_env_config_recorded_as_given(ppo_seeds):
    """The env settings are an EnvConfig like every env-building kind's (flat on the command line); what
    was not given stays each run's own, in config.toml too, so that a run's history survives a re-run."""
    import tomllib

    from motorlab.envs import EnvConfig
    from motorlab.kinds.robustness import ROBUSTNESS

    settings = ROBUSTNESS.make(policies=[str(ppo_seeds / "seed0")], vary=["delay=0:0.1:2"], push_body="pole")
    assert isinstance(settings.env, EnvConfig) and settings.env.push_body == "pole"
    assert settings.config()["env"] == {"push_body": "pole"}
    again = ROBUSTNESS.validate(settings.config())  # a job's settings, a study's re-run
    (run,) = subjects(again.policies, again.env)
    assert run.env.history == 2 and run.env.push_body == "pole"
    assert "env" not in ROBUSTNESS.make(policies=["pid"], vary=["delay=0:0.1:2"]).config()
    # config.toml written before: the env as an id, or as a table of the settings given
    old = ROBUSTNESS.validate(tomllib.loads(f'policies = ["pid"]\nvary = ["delay=0:0.1:2"]\nenv = "{ENV_ID}"\n'))
    assert old.env == EnvConfig(id=ENV_ID) and subjects(old.policies, old.env)[0].env.id == ENV_ID
    table = ROBUSTNESS.validate(tomllib.loads('policies = ["pid"]\nvary = ["delay=0:0.1:2"]\n'
                                              f'[env]\nid = "{ENV_ID}"\ndelay_on = "action"\n'))
    assert table.env.delay_on == "action" and table.config()["env"] == {"id": ENV_ID, "delay_on": "action"}


def test_reward_shaping_is_refused_in_one_line(tmp_path):
    from motorlab.kinds.robustness import ROBUSTNESS

    with pytest.raises(MotorlabError, match=r"^env\.reward 'alive': robustness reports the env's own return"):
        ROBUSTNESS.make(policies=["pid"], vary=["delay=0:0.1:2"], env={"id": ENV_ID, "reward": "alive"})
    proc = run_here("robustness", "pid", "--env", ENV_ID, "--vary", "delay=0:0.1:2", "--delay-on", "sideways",
                    "--out", tmp_path / "out")
    assert_one_line_error(proc, "--delay-on")
    assert not (tmp_path / "out").exists()


def test_cli_errors_are_one_line(tmp_path):
    assert_one_line_error(run_here("robustness", "pid", "--env", ENV_ID, "--vary", "delya=0:1:3",
                                   "--out", tmp_path / "a"), "did you mean delay")
    assert_one_line_error(run_here("robustness", "pid", "--env", ENV_ID, "--vary", "push-force=0:10:3",
                                   "--out", tmp_path / "b"), "--push-body")
    assert_one_line_error(run_here("robustness", "pid", "--vary", "delay=0:0.2:3", "--out", tmp_path / "c"),
                          "--env")
    assert_one_line_error(run_here("robustness", "pid", "--env", ENV_ID, "--vary", "delay=0:0.2:3",
                                   "--vary", "delay=0:0.1:2", "--out", tmp_path / "d"), "twice")
    assert not any((tmp_path / x).exists() for x in "abcd")


def test_holds_is_the_widest_band_not_only_from_zero():
    """A policy trained under a 0.2 s delay fails without delay and holds around it."""
    import numpy as np

    from motorlab.robustness_curves.curves import Curves, Point

    axis = parse_axis("delay=0,0.1,0.2,0.3")
    ok = {"delay-trained": [0, 1, 1, 0], "plain": [1, 1, 0, 0], "never": [0, 0, 0, 0]}
    points = [Point(g, g, "delay", v, np.full(10, 1000.0 * o), np.full(10, 1000), np.full(10, bool(o)), 0)
              for g, row in ok.items() for v, o in zip(axis.values, row, strict=True)]
    curves = Curves([axis], list(ok), points, "success", 10)
    assert curves.holds("delay-trained", "delay") == (0.1, 0.2)
    assert curves.holds("plain", "delay") == (0.0, 0.1)
    assert curves.holds("never", "delay") is None
