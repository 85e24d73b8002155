"""What every training loop shares: periodic deterministic evaluation, the
steps-to-success rule, metrics.csv rows and TensorBoard scalars.

Steps-to-success: the env steps used to produce the first policy for which
`solve_episodes` deterministic evaluation episodes all reach `solve_return`.
"""

from __future__ import annotations

import itertools
import os
import socket
import time
from collections import deque
from pathlib import Path

import numpy as np
from tensorboard.compat.proto.event_pb2 import Event
from tensorboard.compat.proto.summary_pb2 import Summary
from tensorboard.summary.writer.record_writer import RecordWriter

from motorlab import trackers
from motorlab.evaluation import Evaluator
from motorlab.faults import FAULT_KEY, FAULTS_LOG
from motorlab.policies import Policy
from motorlab.rl.config import TrainConfig
from motorlab.runs import METRICS, MetricsWriter

METRIC_FIELDS = ["timesteps", "wall_seconds", "episode_return", "episode_length", "episode_success",
                 "success_rate_100", "eval_return_mean", "eval_return_min", "eval_success_rate", FAULT_KEY, "train_seconds"]

_FILES = itertools.count()  # event files this process opened: a unique name even within one second
EVAL_SEED_OFFSET = 10_000  # evaluation episodes never share seeds with training episodes


class ScalarWriter:
    """TensorBoard scalars as torch's SummaryWriter writes them (the same event file name and records: one
    Summary simple_value per scalar, wall time and step), without torch (an LQR run does not import it, and
    starts a second sooner) and without a writer thread. tensorboard's EventFileWriter writes from a
    thread that its close() joins; a stop signal landing while training wrote a scalar left that join
    waiting until the worker's grace ran out and the kernel ended it (seen under load: exit -14 in place
    of 130). Written here in the caller's thread, a close is a file's close: nothing to wait for."""

    def __init__(self, log_dir: Path | str):
        folder = Path(log_dir)
        folder.mkdir(parents=True, exist_ok=True)
        name = f"events.out.tfevents.{int(time.time()):010d}.{socket.gethostname()}.{os.getpid()}.{next(_FILES)}"
        self._file = open(folder / name, "wb")  # buffered: flushed at each evaluation and at close
        self._records = RecordWriter(self._file)
        self._write(Event(wall_time=time.time(), file_version="brain.Event:2"))
        self.flush()

    def add_scalar(self, tag: str, scalar_value: float, global_step: int | None = None,
                   walltime: float | None = None) -> None:
        value = float(np.asarray(scalar_value).squeeze())
        event = Event(summary=Summary(value=[Summary.Value(tag=tag, simple_value=value)]))
        event.wall_time = time.time() if walltime is None else walltime
        if global_step is not None:
            event.step = int(global_step)
        self._write(event)

    def _write(self, event: Event) -> None:
        self._records.write(event.SerializeToString())

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        self._file.close()  # flushes first


class TrainingMonitor:
    """Evaluates, logs and decides when a run is solved.

    Args:
        cfg: the training settings.
        run_dir: where metrics.csv and tensorboard/ go.
        solve_return: return every evaluation episode must reach (None: no target).
    """

    def __init__(self, cfg: TrainConfig, run_dir: Path, solve_return: float | None, resume: dict | None = None):
        self.cfg = cfg
        self.solve_return = solve_return
        self.evaluator = Evaluator(cfg.env, cfg.solve_episodes, cfg.seed + EVAL_SEED_OFFSET)
        steps = resume["steps"] if resume else None
        self.metrics = MetricsWriter(Path(run_dir) / METRICS, METRIC_FIELDS, keep_until=steps)
        self.faults_log = Path(run_dir) / FAULTS_LOG
        if resume is None:
            self.faults_log.unlink(missing_ok=True)
        # its scalars also go to the tracked run, if any (--track; motorlab.trackers)
        self.tb = trackers.mirror(ScalarWriter(Path(run_dir) / "tensorboard" / "motorlab"))
        self.t0 = time.perf_counter()
        self.recent = deque(maxlen=100)
        self.recent_success: deque[bool] = deque(maxlen=100)
        self.episodes = 0
        self.faults = 0
        self.steps_to_success: int | None = None
        self.last_eval_steps = -1
        self.evaluations = 0
        # seconds spent evaluating and checkpointing: not training, so not counted against --minutes
        # (learners evaluated at different cadences meet the same budget of training)
        self.paused = 0.0
        self.out_of_time = False  # stopped by --minutes
        if resume is not None:
            self.restore(monitor_record(resume))

    def state(self) -> dict:
        """What a checkpoint keeps of the monitor (JSON)."""
        return {"wall": self.wall(), "recent": list(self.recent), "recent_success": list(self.recent_success),
                "episodes": self.episodes, "faults": self.faults, "steps_to_success": self.steps_to_success,
                "last_eval_steps": self.last_eval_steps, "evaluations": self.evaluations, "paused": self.paused}

    def restore(self, state: dict) -> None:
        self.t0 = time.perf_counter() - state["wall"]
        self.recent.extend(state["recent"])
        self.recent_success.extend(state["recent_success"])
        for key in ("episodes", "faults", "steps_to_success", "last_eval_steps", "evaluations"):
            setattr(self, key, state[key])
        self.paused = state.get("paused", 0.0)  # checkpoints written before --minutes existed

    def wall(self) -> float:
        return time.perf_counter() - self.t0

    def train_seconds(self) -> float:
        """Wall seconds spent training: the run's wall time less its evaluations and checkpoints."""
        return self.wall() - self.paused

    def pause(self, started: float) -> None:
        """Count the time since `started` (time.perf_counter()) as not training."""
        self.paused += time.perf_counter() - started

    def episode(self, steps: int, ret: float, length: int, success: bool | None = None, fault: str | None = None) -> None:
        """A finished training episode; `success` is "solved at any step" where the env says."""
        self.episodes += 1
        self.recent.append(ret)
        wall = self.wall()  # both clocks from one reading
        row = {"timesteps": steps, "wall_seconds": wall, "train_seconds": wall - self.paused,
               "episode_return": ret, "episode_length": length}
        self.tb.add_scalar("train/episode_return", ret, steps)
        self.tb.add_scalar("train/episode_return_mean100", float(np.mean(self.recent)), steps)
        if success is not None:
            self.recent_success.append(bool(success))
            row["episode_success"] = int(success)
            row["success_rate_100"] = self.success_rate()
            self.tb.add_scalar("train/success_rate_100", row["success_rate_100"], steps)
        if fault:
            self.faults += 1
            row[FAULT_KEY] = 1
            self.tb.add_scalar("train/numerical_faults", self.faults, steps)
            with open(self.faults_log, "a") as f:  # the reason, one line per faulted episode
                f.write(f"timesteps={steps} episode_return={ret:.6g} length={length}: {fault}\n")
        self.metrics.write(row)

    def success_rate(self) -> float | None:
        """Success rate over the last 100 training episodes (None if the env reports none)."""
        return float(np.mean(self.recent_success)) if self.recent_success else None

    def evaluate(self, steps: int, policy: Policy) -> bool:
        """Evaluate `policy` (trained on `steps` env steps); True when solved."""
        started = time.perf_counter()
        stop_below = self.solve_return if self.cfg.until_solved else None
        result = self.evaluator.run(policy, stop_below=stop_below)
        self.last_eval_steps = steps
        self.evaluations += 1
        solved = (not result.aborted and self.solve_return is not None
                  and bool(np.all(result.returns >= self.solve_return)))
        s = result.summary()
        self.pause(started)
        wall = self.wall()
        self.metrics.write({"timesteps": steps, "wall_seconds": wall, "train_seconds": wall - self.paused,
                            "eval_return_mean": s["return_mean"],
                            "eval_return_min": s["return_min"], "eval_success_rate": 1.0 if solved else s["success_rate"]})
        self.tb.add_scalar("eval/return_mean", s["return_mean"], steps)
        self.tb.add_scalar("eval/return_min", s["return_min"], steps)
        self.tb.add_scalar("eval/solved", float(solved), steps)
        self.tb.flush()  # an evaluation's scalars on disk with its metrics.csv row
        if solved and self.steps_to_success is None:
            self.steps_to_success = int(steps)
        return solved

    def close(self) -> None:
        self.metrics.close()
        self.tb.close()
        self.evaluator.close()


def monitor_record(record: dict) -> dict:
    """The training monitor's state in a checkpoint record (latest.json): "monitor", or "tracker"
    in checkpoints written before rl/tracking.py became rl/monitor.py."""
    return record["monitor"] if "monitor" in record else record["tracker"]
