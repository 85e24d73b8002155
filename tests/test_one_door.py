"""Every entry point runs a step through one door, `StepKind.perform`: the command line, a worker (the
child every study seed, sweep trial and tune trial runs in), a study's own steps, and the Python API.
A test patches the door and sees each of them call it."""

from __future__ import annotations

import pytest
from rich.console import Console

from motorlab.stepkind import StepKind
from tests.helpers import ENV_ID, assert_ok, read_summary, run_here

pytestmark = pytest.mark.fast


@pytest.fixture
def door(monkeypatch):
    """Every call through the door: (kind, folders, resume), the door still doing its work."""
    calls: list[tuple[str, str | None, bool]] = []
    real = StepKind.perform

    def perform(self, settings, out=None, **kw):
        calls.append((self.name, kw.get("folders"), kw.get("resume", False)))
        return real(self, settings, out, **kw)

    monkeypatch.setattr(StepKind, "perform", perform)
    return calls


def test_the_command_line_goes_through_the_door(door, tmp_path):
    assert_ok(run_here("evaluate", "pid", "--env", ENV_ID, "--episodes", "1", "--out", tmp_path / "e"))
    assert door == [("evaluate", "new", False)]
    assert_ok(run_here("evaluate", "pid", "--env", ENV_ID, "--episodes", "1", "--overwrite", "--out", tmp_path / "e"))
    assert door[-1] == ("evaluate", "overwrite", False)
    assert read_summary(tmp_path / "e")["episodes"] == 1


def test_a_worker_goes_through_the_door(door, tmp_path):
    from motorlab import jobs
    from motorlab.worker import run_job

    job = jobs.job("evaluate", {"policy": "pid", "env": {"id": ENV_ID}, "episodes": 1}, {"out": tmp_path / "w"})
    run_job(job, Console(file=open("/dev/null", "w")))  # noqa: SIM115
    assert door == [("evaluate", "new", False)] and (tmp_path / "w" / "summary.json").is_file()


def test_a_studys_steps_go_through_the_door(door, tmp_path):
    from motorlab.recipes import parse_recipe
    from motorlab.studies import run_study

    recipe = parse_recipe(f"""
name = "door"
[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"
env = "{ENV_ID}"
episodes = 1
[[steps]]
name = "zero"
kind = "evaluate"
policy = "zero"
env = "{ENV_ID}"
episodes = 1
""")
    run_study(recipe, tmp_path / "study", console=Console(file=open("/dev/null", "w")))  # noqa: SIM115
    assert door == [("evaluate", None, False), ("evaluate", None, False)]  # under the study's own folder mode


def test_the_python_api_goes_through_the_door(door, tmp_path):
    import motorlab

    motorlab.evaluate("pid", env=ENV_ID, episodes=1, out=tmp_path / "api", progress=False)
    assert door == [("evaluate", "new", False)]


def test_a_sweeps_trials_are_worker_jobs(tmp_path):
    """A sweep's trials (and a search's: the same launcher) run as job files the worker runs (through the
    door, above): each trial's job names the kind and writes the trial's folder."""
    import json

    from tests.helpers import run_cli

    out = tmp_path / "sweep"
    assert_ok(run_cli("sweep", f"evaluate pid --env {ENV_ID} --episodes 1", "--seeds", "2", "--out", out))
    jobs = sorted((out / "logs").glob("*.job.json"))
    assert len(jobs) == 2
    for path in jobs:
        job = json.loads(path.read_text())
        assert job["command"] == "evaluate" and (tmp_path / job["how"]["out"] / "summary.json").is_file()


def test_orchestration_asks_the_kind_not_a_field():
    """What studies and sweeps need of a kind comes through its interface: its seed field, whether a run may
    stop early, the budget a censored seed is counted at."""
    from motorlab.kinds import KINDS
    from motorlab.rl.config import resolve
    from motorlab.rl.steps import TRAIN

    for k in KINDS.values():
        assert k.takes_seed() == (k.SEED in k.settings.model_fields)
        assert k.budget({"timesteps": 500}) is None or k is TRAIN
    cfg = resolve({"env": {"id": ENV_ID}, "until_solved": True})
    assert TRAIN.stops_early(cfg) and not TRAIN.stops_early(cfg.model_copy(update={"until_solved": False}))
    assert TRAIN.seeded(cfg, 7).seed == 7 and TRAIN.with_seed({"algo": "ppo"}, 3) == {"algo": "ppo", "seed": 3}
    assert TRAIN.budget({"timesteps": 500}) == 500 and TRAIN.budget({"timesteps": True}) is None
    assert TRAIN.budget({}) is None
