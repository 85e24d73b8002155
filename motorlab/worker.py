"""`python -m motorlab.worker JOB.json`: the one entry point of motorlab's child processes.

A study's seeds, a sweep's or search's trials and Ray's workers each run one job (motorlab.jobs):
the command it names, from its settings, through the same `Command.invoke` the CLI calls, then
the same printout, into the process's log. Mistakes are one line and status 2, as on the command
line; SIGINT (a stopped trial: the launcher's request), SIGTERM (its parent died, or `kill`) and
SIGHUP stop it as Ctrl-C stops the CLI, with status 128 + the signal (130 for SIGINT).
"""

from __future__ import annotations

import os
import signal
import sys

from motorlab import processes

# Ray's workers block SIGINT, and a process they start inherits the blocked mask: a trial would
# never see the Ctrl-C that stops it early (motorlab.launcher._stop), only the kill after it.
processes.unblock()
# A shell without job control starts a background command (`motorlab tune ... &`, nohup in a
# script) with SIGINT ignored, and children inherit that: the Ctrl-C that stops a pruned trial
# would be lost and the seed would train to its budget. This process is stopped only by its parent.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
# A parent killed outright (SIGKILL, the OOM killer) cannot stop us: the kernel sends SIGTERM then.
processes.die_with_launcher()
os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path  # noqa: E402

from rich.console import Console  # noqa: E402

from motorlab import jobs, trackers  # noqa: E402
from motorlab.cli import one_line_errors  # noqa: E402
from motorlab.errors import MotorlabError  # noqa: E402
from motorlab.registry import BY_NAME  # noqa: E402
from motorlab.user_modules import import_modules  # noqa: E402


def run_job(job: jobs.Job, console: Console) -> None:
    """Run `job` here (what the child process does; tests call it in-process too)."""
    if job.command not in BY_NAME:
        raise MotorlabError(f"the job names no command motorlab knows: {job.command!r}.")
    import_modules(job.imports, "named by the job")
    cmd = BY_NAME[job.command]
    how = cmd.how(**job.how)
    settings = cmd.make(how, **job.settings)  # as the command line makes them: under what `how` brings
    with trackers.adopted(job.tracking):
        if job.resume:  # the run's own settings, continued where its checkpoint is
            result = cmd.perform(settings, Path(job.how["out"]), folders="resume", resume=True, console=console,
                                 progress=job.progress)
        else:
            result = cmd.invoke(settings, how, console=console, progress=job.progress)
    cmd.report(result, settings, console)


def main() -> None:
    # its parent's stop requests, even if ignored; a cleanup that hangs ends before the launcher's kill would
    with one_line_errors(take=(signal.SIGINT, signal.SIGTERM), grace=15.0):
        if len(sys.argv) != 2:
            raise MotorlabError("usage: python -m motorlab.worker JOB.json (a job file a study, sweep or search wrote).")
        run_job(jobs.read(Path(sys.argv[1])), Console(width=150))
    sys.exit(0)


if __name__ == "__main__":
    main()
