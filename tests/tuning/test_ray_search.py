"""motorlab tune --backend ray: the same search through Ray Tune (OptunaSearch, ASHA), the study in
the same database (issue 24). A file of its own so that make test runs it beside test_tune.py."""

from __future__ import annotations

import json

import pytest

from tests.helpers import assert_one_line_error, run_cli, run_here
from tests.tuning.test_tune import BASE, _study

# ---- the ray backend: motorlab tune --backend ray (Ray Tune: OptunaSearch, ASHA) ----------------------------

RAY_SEARCH = ["--space", "solve_return=choice:1000,5000", "--space", "delay=uniform:0.05,0.2", "--seeds", "2",
              "--report-every", "100", "--sampler", "random", "--fresh-seeds", "0", "--study-name", "ray"]


def _live_processes(folder) -> list[str]:
    """Command lines of the processes still running that name `folder` (Linux /proc)."""
    from pathlib import Path

    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            text = cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if str(folder) in text:
            found.append(text)
    return found


def test_ray_backend_searches_on_a_cluster_and_asha_stops_a_hopeless_trial(ray_address, tmp_path):
    """3 trials × 2 seeds on a local Ray head. The study queues the first two (Optuna's
    enqueue_trial; queued trials run first): one that solves in ~100 steps, then a hopeless one
    (solve_return 5000 is never reached), which ASHA stops at its first rung (step 300) with its
    seeds interrupted, long before their 1500-step budget."""
    import optuna

    from motorlab.intervals import across_seeds
    from motorlab.runs import last_timesteps
    from motorlab.tuning.objective import Objective
    from tests.helpers import assert_ok

    out = tmp_path / "t"
    out.mkdir()
    queued = optuna.create_study(storage=f"sqlite:///{out / 'study.db'}", study_name="ray", direction="minimize")
    queued.enqueue_trial({"solve_return": "1000", "delay": 0.1})
    queued.enqueue_trial({"solve_return": "5000", "delay": 0.1})
    argv = ["tune", BASE, *RAY_SEARCH, "--trials", "3", "--backend", "ray", "--address", ray_address, "--out", out]
    proc = run_cli(*argv)
    assert_ok(proc)
    kept = (out / "trials" / "0" / "seed0" / "summary.json").stat().st_mtime_ns
    again = run_cli(*argv, "--resume")  # the same command again: every trial is finished, nothing runs
    assert "ASHA" in proc.stdout and "trial 1 stopped by ASHA at step 300" in proc.stdout
    assert not _live_processes(out / "trials")  # every seed process ended, the stopped ones too

    study = _study(out)
    trials = study.trials
    assert len(trials) == 3 and [t.params["solve_return"] for t in trials[:2]] == ["1000", "5000"]
    good, hopeless = trials[0], trials[1]
    assert good.state == optuna.trial.TrialState.COMPLETE and hopeless.state == optuna.trial.TrialState.PRUNED
    objective = Objective.make("steps_to_success", None)
    for t in trials:
        dirs = [out / "trials" / str(t.number) / f"seed{s}" for s in (0, 1)]
        assert t.user_attrs["run_dirs"] == [str(d) for d in dirs]
        assert t.user_attrs["settings"]["solve_return"] == t.params["solve_return"]
        assert t.intermediate_values and all(step % 100 == 0 for step in t.intermediate_values)
        for step, value in t.intermediate_values.items():  # the IQM over the seeds at that step
            assert value == pytest.approx(across_seeds([objective.progress(d, step) for d in dirs]).value)
        if t.state == optuna.trial.TrialState.COMPLETE:
            per_seed = [json.loads((d / "summary.json").read_text())["steps_to_success"] for d in dirs]
            assert t.user_attrs["seed_values"] == pytest.approx(per_seed)
            assert t.value == pytest.approx(across_seeds(per_seed).value)
    # the hopeless trial: stopped at step 300, its seeds interrupted (Ctrl-C, not killed), unfinished
    assert max(hopeless.intermediate_values) == 300
    hopeless_dirs = [out / "trials" / "1" / f"seed{s}" for s in (0, 1)]
    for d in hopeless_dirs:
        assert not (d / "summary.json").exists() and 300 <= last_timesteps(d) < 1500
        assert "interrupted" in (out / "trials" / "1" / "logs" / f"{d.name}.log").read_text()
    assert hopeless.user_attrs["env_steps_saved"] > 1500

    # what Tune got: real numbers, at increasing env steps, the last one the final IQM with the seeds' values
    rows = [json.loads(line) for line in (out / "ray" / "tune" / "trial0" / "result.json").read_text().splitlines()]
    steps = [r["env_steps"] for r in rows if not r.get("final")]
    assert steps == sorted(set(steps)) and steps[0] == 100
    assert {r["env_steps"]: r["steps_to_success"] for r in rows if not r.get("final")} == good.intermediate_values
    assert rows[-1]["final"] and rows[-1]["steps_to_success"] == pytest.approx(good.value)
    assert rows[-1]["seed_values"] == pytest.approx(good.user_attrs["seed_values"])
    stopped = [json.loads(line) for line in (out / "ray" / "tune" / "trial1" / "result.json").read_text().splitlines()]
    assert [r["env_steps"] for r in stopped] == [100, 200, 300] and not any("seed_values" in r for r in stopped)

    # tune's outputs, as for the local backend
    assert "solve_return = 1000" in (out / "best.toml").read_text()
    csv_rows = (out / "trials.csv").read_text().splitlines()
    assert csv_rows[1].startswith("0,COMPLETE,1000,0.1,") and csv_rows[2].startswith("1,PRUNED,5000,")

    assert_ok(again)
    assert "3 of 3 trials finished" in again.stdout
    assert len(_study(out).trials) == 3
    assert (out / "trials" / "0" / "seed0" / "summary.json").stat().st_mtime_ns == kept


def test_ray_backend_address_errors_are_one_line(tmp_path):
    import time

    from tests.helpers import free_port

    t0 = time.monotonic()
    proc = run_here("tune", BASE, *RAY_SEARCH, "--trials", "1", "--backend", "ray",
                    "--address", f"127.0.0.1:{free_port()}", "--out", tmp_path / "t")
    assert_one_line_error(proc, "no Ray cluster answers")
    assert time.monotonic() - t0 < 30 and not (tmp_path / "t").exists()
    assert_one_line_error(run_here("tune", BASE, *RAY_SEARCH, "--address", "h:1", "--out", tmp_path / "t"),
                          "add --backend ray")
    assert not (tmp_path / "t").exists()


def test_ray_backend_asha_starts_from_the_studys_earlier_trials():
    """A resumed search's ASHA already holds the study's earlier trials at its rungs: a new trial
    that is worse than them at a rung is stopped there, as the local pruner would."""
    import optuna
    from ray.tune.schedulers import TrialScheduler

    from motorlab.tuning.ray_study import StudyASHA

    study = optuna.create_study(direction="minimize")
    dist = {"x": optuna.distributions.FloatDistribution(0, 1)}
    for value, curve in ((100.0, {100: 100.0, 200: 100.0, 300: 100.0}), (150.0, {100: 100.0, 300: 150.0})):
        study.add_trial(optuna.trial.create_trial(params={"x": 0.5}, distributions=dist, value=value,
                                                  intermediate_values=curve))
    study.add_trial(optuna.trial.create_trial(state=optuna.trial.TrialState.FAIL))  # not a rung's
    asha = StudyASHA(study.trials, time_attr="env_steps", metric="steps_to_success", mode="min", max_t=900,
                     grace_period=300, reduction_factor=3, stop_last_trials=False)
    rungs = dict(asha._brackets[0]._rungs)
    assert rungs[300] == {"study-trial-0": -100.0, "study-trial-1": -150.0} and rungs[900] == {}

    class New:
        trial_id = "new"

    assert asha._brackets[0].on_result(New(), 300, -300.0) == TrialScheduler.STOP  # worse than both at step 300
