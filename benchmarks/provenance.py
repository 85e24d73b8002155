"""Where a benchmark's numbers come from: the commit, the packages, the machine and its load, and a
result file written whole (temp file, then rename). Shared by the benchmarks that record results."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import tempfile
from importlib import metadata
from pathlib import Path

HERE = Path(__file__).resolve().parent


def git_state(at_start: dict | None = None) -> dict:
    """The commit and the files changed beside it. Given `at_start` (this, read when the run began), it
    is returned, with `changed_during_run`: a run's processes load its code as they start, so the tree
    at its end need not be what ran (an edit or a commit made meanwhile)."""
    def git(*args: str) -> str:  # not stripped: a porcelain line starts with its status columns
        return subprocess.run(["git", *args], cwd=HERE, capture_output=True, text=True, check=True).stdout

    try:
        changed = [line[3:] for line in git("status", "--porcelain").splitlines() if line.strip()]
        now = {"commit": git("rev-parse", "HEAD").strip(), "dirty": bool(changed), "changed_files": changed}
    except (OSError, subprocess.CalledProcessError) as e:
        now = {"commit": None, "error": str(e)}
    if at_start is None:
        return now
    return {**at_start, "changed_during_run": now != at_start, **({"at_end": now} if now != at_start else {})}


def versions() -> dict:
    out = {}
    for pkg in ("motorlab", "torch", "mujoco", "gymnasium", "stable-baselines3", "scipy", "numpy"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            out[pkg] = None
    return {"python": platform.python_version(), **out}


def cpu_model() -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def load() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()]


def write_result(out: dict, path: Path) -> None:
    """The JSON at `path`, through a temporary file renamed over it (a reader never sees half of it)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(out, f, indent=2)
            f.write("\n")
        os.chmod(tmp, 0o644)  # mkstemp's file is private
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class Recorder:
    """One run of a benchmark script, recorded: the git state and the load average are read when it
    starts (what ran is the code its processes loaded then); `record` adds the date, the command
    line, the package versions, the machine and the load at the end, writes
    benchmarks/results/<name>.json whole (a newer run of the same script replaces it) and prints it."""

    def __init__(self, name: str, results: Path = HERE / "results"):
        import sys

        self.name, self.results = name, results
        self.argv = sys.argv[1:]
        self.git = git_state()
        self.load = load()

    def record(self, result: dict, file: str | None = None) -> dict:
        import datetime

        # a script's own "machine" entry is kept beside these facts, not replaced by them
        reported = result.get("machine")
        reported = reported if isinstance(reported, dict) else {} if reported is None else {"reported": reported}
        out = {"benchmark": self.name, **result,
               "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               "argv": self.argv, "git": git_state(at_start=self.git), "versions": versions(),
               "machine": {**reported, "cpu": cpu_model(), "cores": os.cpu_count(), "load_average_start": self.load,
                           "load_average_end": load()}}
        write_result(out, self.results / f"{file or self.name}.json")
        print(json.dumps(out, indent=2))
        return out
