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
    from motorlab.kinds.train import TRAIN
    from motorlab.rl.config import resolve

    for k in KINDS.values():
        assert k.takes_seed() == (k.SEED in k.settings.model_fields)
        assert k.budget({"timesteps": 500}) is None or k is TRAIN
    cfg = resolve({"env": {"id": ENV_ID}, "until_solved": True})
    assert TRAIN.stops_early(cfg) and not TRAIN.stops_early(cfg.model_copy(update={"until_solved": False}))
    assert TRAIN.seeded(cfg, 7).seed == 7 and TRAIN.with_seed({"algo": "ppo"}, 3) == {"algo": "ppo", "seed": 3}
    assert TRAIN.budget({"timesteps": 500}) == 500 and TRAIN.budget({"timesteps": True}) is None
    assert TRAIN.budget({}) is None
    assert TRAIN.planned_steps(cfg.model_copy(update={"timesteps": 700})) == 700
    for k in KINDS.values():  # a kind's budget field is one of its settings; without one, none is planned
        assert k.BUDGET is None or k.BUDGET in k.settings.model_fields
        assert k.BUDGET is not None or k.planned_steps_of({"timesteps": 500}) is None


def test_a_tune_trial_budget_is_what_its_kind_reads_from_the_run_folder(tmp_path):
    """The tune objective asks the run folder's kind (its claim) for the budget: a train folder's
    config.toml timesteps; a folder of a kind without a budget, or unclaimed, has none."""
    from motorlab import claims
    from motorlab.runs import write_toml
    from motorlab.tuning.objective import budget_of

    for kind, expected in (("train", 1234), ("evaluate", None)):
        folder = tmp_path / kind
        folder.mkdir()
        write_toml(folder / "config.toml", {"timesteps": 1234, "seed": 0})
        assert budget_of(folder) is None  # not claimed yet
        claims.mark(folder, kind)
        assert budget_of(folder) == expected


@pytest.mark.parametrize(("target", "space", "expected"), [
    ("train InvertedPendulum-v5 --algo ppo --timesteps 3000", ["lr=loguniform:1e-4,1e-3"], 3000),
    ("train InvertedPendulum-v5 --algo ppo", ["lr=loguniform:1e-4,1e-3"], "default"),  # the kind's default budget
    ("train InvertedPendulum-v5 --algo ppo --timesteps 3000", ["timesteps=int:1000,5000"], None),  # searched over
    ("evaluate runs/x --episodes 3", ["episodes=int:1,5"], None),  # a kind without a budget
])
def test_ray_asha_budget_comes_from_the_targets_kind(tmp_path, target, space, expected):
    """ASHA's max_t is the budget the target's kind plans (its settings, defaults included), not a
    --timesteps read from the command text; unknown when the search varies it or the kind has none."""
    from motorlab.kinds.train import TRAIN
    from motorlab.sweeps.targets import read_target
    from motorlab.tuning.ray_search import budget
    from motorlab.tuning.space import parse_space
    from motorlab.tuning.trials import Planner
    from motorlab.tuning.tune import make_spec

    spec = make_spec(read_target(target, "tune"), parse_space(space), 1, 1, "return", None, tmp_path, None, None,
                     "tpe", "median", 0, 100, 1, 0)
    planner = Planner(read_target(target, "tune"), spec.space, {})
    if expected == "default":
        expected = TRAIN.settings.model_fields["timesteps"].default
    assert budget(spec, planner) == expected
