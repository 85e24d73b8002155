"""Steps of a study that need nothing from each other, run at the same time.

A step needs the steps it names ("@step"). With `parallel_steps = K` (a recipe field, or
`motorlab run --parallel-steps K`), every train step whose inputs are ready starts in the
background as its own `motorlab train` process, at most K at once, while this process runs
the short steps (collect, fit, zero-shot, ...) as soon as their inputs exist. The SAR hand
study is two chains, play -> collect -> fit -> SAR-RL and RL-E2E, which needs nothing: one
SAC run leaves cores idle while its env processes wait for the learner and the learner for
them, and a second run fills those gaps. Each step's results are the ones it gives alone
(same settings, same seeds, its own process); only wall times change, and the table says
which steps ran beside which.
"""

from __future__ import annotations

import contextvars
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from motorlab.recipes import Step

RunStep = Callable[[Step, bool, threading.Event], Any]  # (step, in the background, stop) -> what it found
ProgressOf = Callable[[Step], tuple[int, int]]  # (done, total) of a training step


@dataclass
class _Job:
    step: Step
    thread: threading.Thread | None = None
    result: Any = None
    error: BaseException | None = None
    t0: float = field(default_factory=time.perf_counter)


class Overlaps:
    """Which steps ran while each step ran (for the table: its wall time is shared)."""

    def __init__(self) -> None:
        self.running: set[str] = set()
        self.beside: dict[str, set[str]] = {}

    def start(self, name: str) -> None:
        self.running.add(name)
        for other in self.running:
            self.beside.setdefault(other, set()).update(self.running - {other})

    def end(self, name: str) -> None:
        self.running.discard(name)


def run_overlapped(steps: list[Step], run: RunStep, limit: int, console: Console, progress_of: ProgressOf,
                   describe: Callable[[Step], str], finish: Callable[[Step], Any] = lambda step: None
                   ) -> tuple[dict[str, Any], Overlaps]:
    """Run `steps` (in recipe order where they are ready), train steps in the background.

    `finish(step)` runs in this thread once a background step is done: work that must not run
    beside the foreground steps (matplotlib's figures are not thread-safe).

    Returns:
        Each step's headline, and which steps overlapped.

    Raises:
        Whatever a step raised (the first failure); Ctrl-C. Either way the background
        trainings are stopped first, as Ctrl-C would stop them, so they can resume.
    """
    results: dict[str, Any] = {}
    overlaps = Overlaps()
    pending = list(steps)
    background: list[_Job] = []
    stop = threading.Event()
    order = {s.name: i for i, s in enumerate(steps, 1)}

    def header(step: Step, how: str = "") -> None:
        console.print(f"[bold][{order[step.name]}/{len(steps)}][/bold] {step.name}: {describe(step)}{how}")

    def start_background(step: Step) -> None:
        job = _Job(step)

        def target() -> None:
            try:
                job.result = run(step, True, stop)
            except BaseException as e:  # handed to the main thread, which raises it
                job.error = e

        # the thread runs in a copy of this context: the run-folder mode and the tracking go with it
        job.thread = threading.Thread(target=contextvars.copy_context().run, args=(target,), name=f"step-{step.name}",
                                      daemon=True)
        overlaps.start(step.name)
        header(step, " (in the background)")
        job.thread.start()
        background.append(job)

    def reap() -> None:
        for job in [j for j in background if not j.thread.is_alive()]:
            background.remove(job)
            overlaps.end(job.step.name)
            if job.error is not None:
                raise job.error
            finish(job.step)
            results[job.step.name] = job.result
            console.print(f"      {job.step.name}: done in {time.perf_counter() - job.t0:.1f} s")

    try:
        while True:
            reap()
            if not (pending or background):
                break
            ready = [s for s in pending if all(n in results for n in s.inputs())]
            train = next((s for s in ready if s.kind.trains), None)
            if train is not None and len(background) < limit:
                pending.remove(train)
                start_background(train)
                continue
            other = next((s for s in ready if not s.kind.trains), None)
            if other is not None:
                pending.remove(other)
                header(other)
                overlaps.start(other.name)
                t0 = time.perf_counter()
                results[other.name] = run(other, False, stop)
                overlaps.end(other.name)
                console.print(f"      done in {time.perf_counter() - t0:.1f} s")
                continue
            _wait_for_one(background, console, progress_of)
    except BaseException:
        stop.set()  # background steps stop their training processes and return
        for job in background:
            job.thread.join()
        raise
    return results, overlaps


def _wait_for_one(background: list[_Job], console: Console, progress_of: ProgressOf) -> None:
    """Show the background trainings' progress (env steps from their metrics) until one ends."""
    assert background, "a step waits for inputs that no running step will produce"  # recipes only name earlier steps
    with Progress(TextColumn("      {task.description}"), BarColumn(), TextColumn("{task.completed:,}/{task.total:,} steps"),
                  TimeElapsedColumn(), console=console, transient=True, disable=not console.is_terminal) as bar:
        tasks = {id(j): bar.add_task(j.step.name, total=max(1, progress_of(j.step)[1])) for j in background}
        while all(j.thread.is_alive() for j in background):
            for j in background:
                bar.update(tasks[id(j)], completed=progress_of(j.step)[0])
            time.sleep(0.5)
