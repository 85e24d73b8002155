"""The trainable of `motorlab tune --backend ray` (ray_search.py): one trial's seeds on a Ray worker.

Ray is imported at module level: this module is imported only once Ray is known to be there
(launcher.init_ray), and Tune pickles SeedTrial by reference, so every worker imports it (and
only what a trial needs: not Optuna's samplers, nor the study's database).

SeedTrial (a class trainable) plans nothing: it starts the trial's seed processes (planned on the
driver, in its config), and each `step` returns the next intermediate number over the seeds
(objective.Objective.combine) at a multiple of --report-every env steps (objective.Reporter, as the local backend reports
to its pruner), with `env_steps` as Tune's time. After the seeds end: the numbers up to the budget
(as the local backend fills them, so later trials are compared with this one there), each with
the trial's final number and the seed values, then the final number alone (`final`, `done`); or why they failed.

When Tune stops the trial (ASHA), `cleanup` stops the seed processes (Ctrl-C, then a kill after a
grace period) and waits for them. A class trainable, because Tune runs `stop` (hence `cleanup`) to
its end before the worker exits, while a function trainable's thread is abandoned when its
worker exits: its `finally` might not run, and the seeds would go on as orphans.
"""

from __future__ import annotations

import math
from typing import Any

from ray import tune

from motorlab.errors import MotorlabError
from motorlab.runs import SUMMARY, read_json
from motorlab.tuning.objective import Objective, Reporter, budget_of, steps_run, trial_horizon
from motorlab.tuning.trials import SeedRuns, run_dirs

POLL_SECONDS = 1.0  # as the local backend's (search.POLL_SECONDS)

JOB = "motorlab"  # the config key holding what the trainable runs (the rest of the config: the sampled values)
STEPS = "env_steps"  # Tune's time for the scheduler: env steps every seed of the trial has reached


def dirname(trial: Any) -> str:
    """Tune's folder of a trial (OUT/ray/tune/trial<n>), named by its study number, as OUT/trials/<n>."""
    return f"trial{trial.config[JOB]['number']}"


class SeedTrial(tune.Trainable):
    """One trial: its seeds' processes, and their numbers as Tune results."""

    def setup(self, config: dict[str, Any]) -> None:
        job = config[JOB]
        self.key = job["objective"]
        self.number = job["number"]
        self.objective = Objective(job["objective"], job["maximize"])
        self.dirs = run_dirs(job["runs"])
        self.reporter = Reporter(self.objective, job["report_every"], self.dirs)
        self.queue: list[dict[str, Any]] = []
        self.seeds = SeedRuns(job["runs"], job["parallel"]).start()

    def step(self) -> dict[str, Any]:
        while not self.queue:
            if self.seeds.running():
                self.seeds.join(POLL_SECONDS)
                self.queue += [self._result(step, value) for step, value in self.reporter.reached()]
            else:
                self.queue += self._end()
        return self.queue.pop(0)

    def save_checkpoint(self, checkpoint_dir: str) -> dict[str, Any]:
        return {}  # nothing to keep: the seeds' run folders are the trial's record

    def load_checkpoint(self, checkpoint: Any) -> None:
        pass

    def cleanup(self) -> None:
        seeds = getattr(self, "seeds", None)
        if seeds is not None:
            seeds.stop()  # Ctrl-C to each running seed, then kill after a grace period; nothing when they ended

    def _result(self, step: int, number: float, **extra: Any) -> dict[str, Any]:
        return {self.key: number, STEPS: step, "trial_number": self.number,
                "env_steps_run": sum(steps_run(d) for d in self.dirs),
                "env_steps_budget": sum(budget_of(d) or 0 for d in self.dirs), **extra}

    def _failed(self, message: str, fatal: bool = False) -> list[dict[str, Any]]:
        return [self._result(self.reporter.last_step, math.nan, failed=message, fatal=fatal, done=True)]

    def _end(self) -> list[dict[str, Any]]:
        """The seeds have ended: the last numbers, then the trial's own (or why they failed)."""
        try:
            self.seeds.wait()
        except Exception as e:  # noqa: BLE001 - the pool itself failed (e.g. cannot start a process)
            return self._failed(f"{type(e).__name__}: {e}")
        failed = self.seeds.failures()
        if failed:
            return self._failed(failed[0])
        try:
            scores = [self.objective.score(read_json(d / SUMMARY)) for d in self.dirs]
        except MotorlabError as e:
            return self._failed(str(e), fatal=True)  # no such number: every trial would fail alike
        value = self.objective.combine([v for v, _ in scores])
        final = {"value": value, "seed_values": [v for v, _ in scores], "seed_censored": [c for _, c in scores]}
        numbers = [*self.reporter.reached(), *self.reporter.filled(trial_horizon(self.dirs))]
        return [*(self._result(step, v, **final) for step, v in numbers),
                self._result(max(self.reporter.last_step, trial_horizon(self.dirs)), value, **final, final=True,
                             done=True)]
