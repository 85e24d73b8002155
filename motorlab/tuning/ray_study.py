"""The driver's side of `motorlab tune --backend ray` (ray_search.py runs it): the searcher that
keeps the study in the database, its heartbeats, and the scheduler. Ray is imported at module
level: this module is imported only once Ray is known to be there (launcher.init_ray).

- StudySearch (Ray's OptunaSearch, on the study's own storage): every Tune trial is an Optuna
  trial of the study from the moment Tune asks for it (RUNNING, with heartbeats, so the trials of
  a driver that died are failed and queued again, as the local backend's), numbered by the study,
  its runs in OUT/trials/<number>/ (planned here, with the Planner). The intermediate numbers go
  to the trial at their env steps; the trial ends COMPLETE (final number and seed values), PRUNED
  (Tune's scheduler stopped it) or FAIL (its seeds failed; or interrupted: queued again by the
  next run), with the user attributes the local backend sets, so that tune.write_results reads
  both backends alike.
- Heartbeat: a Tune callback that keeps the heartbeats of the running trials.
- StudyASHA: Tune's ASHA, its rungs filled beforehand with the study's earlier trials, so that a
  resumed search compares new trials with them (as the local pruner does).
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from typing import TYPE_CHECKING, Any

import optuna
from optuna.trial import TrialState
from ray import tune
from ray.tune.schedulers import AsyncHyperBandScheduler
from ray.tune.search import Searcher
from ray.tune.search.optuna import OptunaSearch

from motorlab.errors import MotorlabError, mask_secrets, mask_url
from motorlab.tuning.outputs import keep_seed_scores, trial_line
from motorlab.tuning.ray_trial import JOB, STEPS
from motorlab.tuning.search import COUNTED, HEARTBEAT_SECONDS, MAX_FAILURES_IN_A_ROW, Counters, counted
from motorlab.tuning.trials import run_dirs

if TYPE_CHECKING:
    from optuna.storages import BaseStorage
    from rich.console import Console

    from motorlab.tuning.search import TuneSpec
    from motorlab.tuning.trials import Planner


class StudySearch(OptunaSearch):
    """Ray's OptunaSearch on the study in the database (see the module's docstring)."""

    def __init__(self, spec: TuneSpec, storage: BaseStorage, sampler: optuna.samplers.BaseSampler, planner: Planner,
                 console: Console, parallel: int, scheduler: str):
        # this search keeps its trials' heartbeats itself (Heartbeat), without Study.optimize
        warnings.filterwarnings("ignore", message="Heartbeat of storage is supposed to be used with Study.optimize")
        super().__init__(space={k: d.distribution() for k, d in spec.space.items()}, metric=spec.objective.key,
                         mode="max" if spec.objective.maximize else "min", sampler=sampler,
                         study_name=spec.study_name, storage=storage)
        self.spec = spec
        self.parallel = parallel  # seed processes at once in a trial: the CPUs it asked for
        self.scheduler = scheduler
        self.counters = Counters()
        self.fatal: str | None = None  # why the search stopped early
        self.finished = False  # said FINISHED to Tune: the search ended (not interrupted)
        self._planner: Planner | None = planner
        self._console: Console | None = console
        self._steps: dict[str, int] = {}
        self._beat = 0.0
        self._wait_until = 0.0

    def __getstate__(self) -> dict[str, Any]:
        """What Tune pickles of this search into OUT/ray/tune/tuner.pkl with its settings. Not the
        planner and console (they stay here), nor the storage, the study and its trials: they hold
        the database URL, password and all; the search's state is the study itself (see `save`)."""
        unpickled = ("_planner", "_console", "_storage", "_ot_study", "_ot_trials")
        state = {k: v for k, v in self.__dict__.items() if k not in unpickled}
        state["spec"] = dataclasses.replace(self.spec, storage=mask_url(self.spec.storage),
                                            target=mask_secrets(self.spec.target))
        return state

    def save(self, checkpoint_path: str) -> None:
        raise NotImplementedError  # the study in the database is the search's state: the same command resumes it

    def _print(self, text: str) -> None:
        if self._console is not None:
            self._console.print(text)

    def _live(self) -> list[str]:
        return [t for t in self._ot_trials if t not in self._completed_trials]

    def beat(self, now: bool = False) -> None:
        """Heartbeats of this process's running trials (at most every HEARTBEAT_SECONDS / 2 unless `now`)."""
        if not now and time.monotonic() - self._beat < HEARTBEAT_SECONDS / 2:
            return
        self._beat = time.monotonic()
        for trial_id in self._live():
            self._storage.record_heartbeat(self._ot_trials[trial_id]._trial_id)

    def suggest(self, trial_id: str) -> dict[str, Any] | str | None:
        """The next trial's settings and seed runs, or None (not now) or FINISHED. Like the local
        backend, a trial starts only while fewer than --trials are finished or running (here or in
        another process sharing the study); trials queued in the study run first."""
        if self.finished:
            return Searcher.FINISHED
        if time.monotonic() < self._wait_until:
            return None
        study = self._ot_study
        have = counted(study)
        running = len(study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)))
        if (self.fatal or self.counters.failures_in_a_row >= MAX_FAILURES_IN_A_ROW or have >= self.spec.trials
                or (have + running >= self.spec.trials and not self._live())):
            self.finished = True
            return Searcher.FINISHED
        if have + running >= self.spec.trials:
            self._wait_until = time.monotonic() + 1.0  # this process's last trials run; one may fail and need a successor
            return None
        super().suggest(trial_id)  # asks the study: a queued trial's settings first, else the sampler's
        trial = self._ot_trials[trial_id]
        values = {k: d.value(trial.params[k]) for k, d in self.spec.space.items()}
        assert self._planner is not None
        try:
            runs = self._planner.plan(values, self.spec.seed_list, self.spec.out / "trials" / str(trial.number))
        except MotorlabError as e:  # a value the command refuses: as the local backend, the search stops
            self.fatal = f"trial {trial.number}: {e}"
            self._completed_trials.add(trial_id)
            self._ot_study.tell(trial, state=TrialState.FAIL)
            self.finished = True
            return Searcher.FINISHED
        trial.set_user_attr("interrupted", False)
        trial.set_user_attr("run_dirs", [str(d) for d in run_dirs(runs)])
        trial.set_user_attr("settings", values)
        trial.set_user_attr("ray_trial_id", trial_id)
        self.beat(now=True)
        shown = ", ".join(f"{k}={v}" for k, v in values.items())
        self._print(f"  trial {trial.number}: {shown} ({len(runs)} seed{'s' * (len(runs) != 1)})")
        job = {"number": trial.number, "runs": runs, "objective": self.spec.objective.key,
               "maximize": self.spec.objective.maximize, "report_every": self.spec.report_every,
               "parallel": self.parallel}
        return {**trial.params, JOB: job}

    def on_trial_result(self, trial_id: str, result: dict[str, Any]) -> None:
        """An intermediate number: the study's trial gets it at its env step (as the local backend's)."""
        trial = self._ot_trials.get(trial_id)
        if trial is None or trial_id in self._completed_trials:
            return
        self.beat()
        self._report(trial_id, result)

    def _report(self, trial_id: str, result: dict[str, Any]) -> None:
        if result.get("final") or "failed" in result or STEPS not in result:
            return
        step = int(result[STEPS])
        if step > self._steps.get(trial_id, 0):
            self._ot_trials[trial_id].report(float(result[self.metric]), step)
            self._steps[trial_id] = step

    def on_trial_complete(self, trial_id: str, result: dict[str, Any] | None = None, error: bool = False) -> None:
        trial = self._ot_trials.get(trial_id)
        if trial is None or trial_id in self._completed_trials:
            return
        self._completed_trials.add(trial_id)
        result = result or {}
        self._report(trial_id, result)  # the number Tune's scheduler stopped it on reaches no on_trial_result
        n = trial.number
        if "seed_values" in result:  # the seeds finished (the scheduler may have stopped it after: no matter)
            censored = result.get("seed_censored") or [False] * len(result["seed_values"])
            scores = [(float(v), bool(c)) for v, c in zip(result["seed_values"], censored)]
            keep_seed_scores(trial, scores)
            trial.set_user_attr("env_steps", int(result["env_steps_run"]))
            self._ot_study.tell(trial, float(result["value"]))
            self.counters.failures_in_a_row = 0
            self.counters.done.append(n)
            self._print(f"  [green]✓[/green] trial {n}: {trial_line(self.spec.objective, scores)}")
        elif "failed" in result or error:
            message = result.get("failed") or (f"Ray Tune's trial failed; see its error.txt under "
                                                f"{self.spec.out / 'ray' / 'tune' / f'trial{n}'}")
            trial.set_user_attr("error", mask_secrets(message))
            self._ot_study.tell(trial, state=TrialState.FAIL)
            self._print(f"  [red]✗[/red] trial {n} failed: {message}")
            if result.get("fatal"):
                self.fatal = message
            else:
                self.counters.failures_in_a_row += 1
                if self.counters.failures_in_a_row >= MAX_FAILURES_IN_A_ROW:
                    self.fatal = f"{MAX_FAILURES_IN_A_ROW} trials in a row failed; the last: trial {n} failed: {message}"
        elif STEPS in result:  # it reported, then Tune's scheduler stopped it
            run, budget = int(result["env_steps_run"]), int(result["env_steps_budget"])
            trial.set_user_attr("env_steps", run)
            trial.set_user_attr("env_steps_saved", max(0, budget - run))
            self._ot_study.tell(trial, state=TrialState.PRUNED)
            self._print(f"  [yellow]✂[/yellow] trial {n} stopped by {self.scheduler} at step {int(result[STEPS]):,} "
                        f"({max(0, budget - run):,} env steps saved)")
        else:  # stopped before it reported anything
            self._interrupted(trial_id)

    def _interrupted(self, trial_id: str) -> None:
        trial = self._ot_trials[trial_id]
        self._completed_trials.add(trial_id)
        trial.set_user_attr("interrupted", True)  # the next `motorlab tune` of the study queues it again
        self._ot_study.tell(trial, state=TrialState.FAIL)

    def settle(self) -> int:
        """After Tune ended: this process's trials that never ended (Ctrl-C) are failed as
        interrupted, to be queued again. Returns how many."""
        live = self._live()
        for trial_id in live:
            self._interrupted(trial_id)
        return len(live)


class Heartbeat(tune.Callback):
    """Keeps the heartbeats of the search's running trials while Tune runs."""

    def __init__(self, search: StudySearch):
        self.search: StudySearch | None = search

    def __getstate__(self) -> dict[str, Any]:  # Tune pickles its settings; the search stays in this process
        return {"search": None}

    def on_step_end(self, iteration: int, trials: list[Any], **info: Any) -> None:
        if self.search is not None:
            self.search.beat()


class StudyASHA(AsyncHyperBandScheduler):
    """ASHA whose rungs already hold the study's earlier trials (COMPLETE and PRUNED) at the rung
    steps they reported: a resumed search judges new trials against them too."""

    def __init__(self, past: list[optuna.trial.FrozenTrial], **kwargs: Any):
        super().__init__(**kwargs)
        for t in past:
            if t.state not in COUNTED:
                continue
            for bracket in self._brackets:
                for milestone, recorded in bracket._rungs:
                    value = t.intermediate_values.get(int(milestone))
                    if value is not None and math.isfinite(value):
                        recorded[f"study-trial-{t.number}"] = self._metric_op * value
