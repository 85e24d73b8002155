"""A job: one command with its settings, handed to a child process as a file.

Studies (a train step's seeds), sweeps, tune and Ray workers run work in processes of their
own. Each gets `(command, settings)` as a JSON file and runs `python -m motorlab.worker JOB`
(motorlab/worker.py): the same `Command.invoke` the CLI and the API call, with the same checks,
and no command line to build or parse on the way. The file also carries what the parent's
context holds and a fresh interpreter would not: the user's env modules and the tracking.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from motorlab import trackers
from motorlab.runs import atomic_path
from motorlab.user_modules import imported_names

JOB_SUFFIX = ".job.json"


@dataclass(frozen=True)
class Job:
    """`command`: the command's name (a step kind's, "run" for a study); `settings`: its settings
    (as config.toml holds them); `how`: its invocation options (out, ...); `resume`: continue the
    interrupted run in `how["out"]` (kinds that can); `progress`: progress bars in the child's log."""

    command: str
    settings: dict[str, Any]
    how: dict[str, Any] = field(default_factory=dict)
    resume: bool = False
    progress: bool = False
    tracking: dict[str, Any] | None = None
    imports: list[str] = field(default_factory=list)

    def identity(self) -> str:
        """What the job does, as text (not how it is tracked): equal for the same work."""
        return json.dumps({"command": self.command, "settings": self.settings, "how": self.how},
                          sort_keys=True, default=str)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def write(self, path: Path) -> Path:
        """The job file, readable by its owner only: it carries what the child needs as given, a tracker's
        credentials included, which every file motorlab records elsewhere masks (errors.mask_secrets)."""
        with atomic_path(Path(path)) as tmp:
            os.chmod(tmp, 0o600)
            tmp.write_text(json.dumps(self.as_dict(), indent=1, default=str))
        return Path(path)


def job(command: str, settings: dict[str, Any], how: dict[str, Any] | None = None, **kw: Any) -> Job:
    """A job for a child started from here: it carries the user's modules (its tracking is the context's
    where it is launched: see `tracked`)."""
    how = {k: str(v) if isinstance(v, Path) else v for k, v in (how or {}).items()}
    return Job(command, json.loads(json.dumps(settings, default=str)), how, imports=list(imported_names()), **kw)


def tracked(job: Job | dict[str, Any]) -> Job:
    """`job` with the tracking of the calling context (trackers and parent run), unless it carries its own
    (a trial handed to a Ray worker got its tracking where the sweep ran)."""
    job = from_dict(job) if isinstance(job, dict) else job
    return job if job.tracking is not None else replace(job, tracking=trackers.handoff())


def read(path: Path) -> Job:
    return from_dict(json.loads(Path(path).read_text()))


def from_dict(data: dict[str, Any]) -> Job:
    return Job(**data)


def process(path: Path) -> list[str]:
    """The command line of the child process that runs the job file `path`."""
    return [sys.executable, "-m", "motorlab.worker", str(path)]
