"""Where a benchmark's numbers come from: the commit, the packages, the machine and its load, and a
result file written whole (temp file, then rename). Shared by the benchmarks that record results."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import subprocess
import tempfile
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

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


# ---------------------------------------------------------------------------------------- development vs headline
#
# A science benchmark (one whose numbers are claims about learning: mbrl, mbrl_bodies) declares two
# disjoint sets of seeds. Settings are chosen on development seeds; a run on them writes one line to
# benchmarks/devlog/<name>.jsonl (the settings tried, their hash, the result) and never a result file.
# A headline runs on seeds no development run used, at a commit with no uncommitted code, and records
# the hash of every setting it used and how many configurations the development log had tried before
# it; it refuses to record when its settings or its code changed while it ran.

DEVLOG = HERE / "devlog"
# paths whose uncommitted changes make a headline's code unknown (results and the devlog are its outputs)
CODE_PATHS = ("motorlab/", "benchmarks/", "pyproject.toml")
OUTPUT_PATHS = ("benchmarks/results/", "benchmarks/devlog/")


@dataclass(frozen=True)
class SeedPlan:
    """A benchmark's development seeds (settings are chosen on them) and its headline seeds (reported,
    never used to choose). A seed also picks its evaluation episodes' reset seeds, so headline seeds
    meet fresh episodes too."""

    development: range
    headline: range

    def __post_init__(self) -> None:
        if set(self.development) & set(self.headline):
            raise ValueError(f"development seeds {_span(self.development)} and headline seeds "
                             f"{_span(self.headline)} overlap")

    def mode(self, seeds: list[int]) -> str:
        """"development" or "headline": the set every seed belongs to; a mix, or a seed in neither, is refused."""
        if not seeds:
            raise SystemExit("no seeds to run")
        dev = [s for s in seeds if s in self.development]
        head = [s for s in seeds if s in self.headline]
        if len(dev) == len(seeds):
            return "development"
        if len(head) == len(seeds):
            return "headline"
        stray = sorted(set(seeds) - set(dev) - set(head))
        raise SystemExit(f"seeds {sorted(seeds)} mix development seeds ({_span(self.development)}) and headline seeds "
                         f"({_span(self.headline)})" + (f", and {stray} are in neither" if stray else "")
                         + ": run one set at a time")


def _span(r: range) -> str:
    return f"{r.start}-{r.stop - 1}"


SCIENCE_SEEDS = SeedPlan(development=range(0, 100), headline=range(100, 1000))


def seed_list(text: str) -> list[int]:
    """"100-104" or "100,102,7": the seeds, in the order given, without repeats."""
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        for s in range(int(lo), int(hi or lo) + 1):
            if s not in out:
                out.append(s)
    return out


def settings_hash(settings: Any) -> str:
    """sha256 of the settings as canonical JSON (sorted keys), first 16 hex digits."""
    text = json.dumps(settings, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def devlog_entries(name: str, devlog: Path = DEVLOG) -> list[dict]:
    path = devlog / f"{name}.jsonl"
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def configurations_tried(entries: list[dict]) -> int:
    """The distinct settings (by hash) a development log tried."""
    return len({e["settings_hash"] for e in entries})


def code_changes(state: dict) -> list[str]:
    """The uncommitted files of a git state that are code (not a benchmark's own outputs)."""
    return sorted(f for f in state.get("changed_files", [])
                  if f.startswith(CODE_PATHS) and not f.startswith(OUTPUT_PATHS))


class Harness:
    """A science benchmark's runs: `start` one on a set of seeds with its settings, `finish` it with its
    result. Development runs append to the devlog; headline runs write results/<file>.json through
    `Recorder`, with the settings' hash and the development log's count of configurations."""

    def __init__(self, name: str, seeds: SeedPlan = SCIENCE_SEEDS, results: Path = HERE / "results",
                 devlog: Path = DEVLOG):
        self.name, self.seeds, self.results, self.devlog = name, seeds, results, devlog

    def start(self, seeds: list[int], settings: Any, *, log: str | None = None,
              in_sample_key: str | None = None) -> HarnessRun:
        """Begin a run on `seeds` with `settings` (every setting it uses, resolved: the catalogue's
        included); `log`: the devlog's name (default the harness's, e.g. mbrl-reacher per env);
        `in_sample_key`: the part of the settings whose development runs a headline shows as its
        in-sample numbers (default: runs with the same hash of all of them)."""
        mode = self.seeds.mode(list(seeds))
        recorder = Recorder(self.name, results=self.results)
        if mode == "headline":
            dirty = code_changes(recorder.git)
            if recorder.git.get("commit") is None or dirty:
                raise SystemExit(f"a headline run needs committed code (its settings frozen at one commit); "
                                 f"uncommitted: {', '.join(dirty) or recorder.git.get('error')}. Commit, or run "
                                 f"from a worktree of the commit (git worktree add)")
        return HarnessRun(self, list(seeds), mode, json.loads(json.dumps(settings, default=str)), recorder,
                          log or self.name, in_sample_key)


@dataclass
class HarnessRun:
    harness: Harness
    seeds: list[int]
    mode: str
    settings: Any
    recorder: Recorder
    log: str
    in_sample_key: str | None = None

    @property
    def settings_hash(self) -> str:
        return settings_hash(self.settings)

    def check_settings(self, used: Any, where: str) -> None:
        """Refuse when settings a part of the run actually used (e.g. a seed's process, resolved there)
        differ from the settings the run started with."""
        used = json.loads(json.dumps(used, default=str))
        if settings_hash(used) != self.settings_hash:
            differ = sorted(k for k in {*used, *self.settings} if used.get(k) != self.settings.get(k)) \
                if isinstance(used, dict) and isinstance(self.settings, dict) else []
            raise SystemExit(f"{where} ran with other settings" + (f" ({', '.join(differ)})" if differ else "") +
                             " than the run started with (the code or the catalogue changed during the run): "
                             "nothing recorded")

    def finish(self, result: dict, file: str | None = None, *, used: dict[str, Any] | None = None) -> dict:
        """Record the run. `used`: {where: settings} as each part of the run resolved them, each checked equal
        to the start's. Development: one devlog line, no result file. Headline: results/<file>.json, refused
        when the settings or the code changed while it ran."""
        for where, settings in (used or {}).items():
            self.check_settings(settings, where)
        import datetime

        date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
        entries = devlog_entries(self.log, self.harness.devlog)
        if self.mode == "development":
            line = {"date": date, "argv": self.recorder.argv, "git": git_state(at_start=self.recorder.git),
                    "seeds": self.seeds, "settings_hash": self.settings_hash, "settings": self.settings,
                    "result": result}
            self.harness.devlog.mkdir(parents=True, exist_ok=True)
            with open(self.harness.devlog / f"{self.log}.jsonl", "a") as f:  # one write per line: appends stay whole
                f.write(json.dumps(line, default=str) + "\n")
            print(json.dumps(line, indent=2, default=str))
            return line
        end = git_state(at_start=self.recorder.git)
        if end.get("changed_during_run"):
            raise SystemExit("the code changed during the headline run (a commit or an edit): nothing recorded; run "
                             "it again from a worktree of one commit")
        key = self.in_sample_key
        same = [e for e in entries if (e["settings_hash"] == self.settings_hash if key is None else
                                       isinstance(e.get("settings"), dict) and key in e["settings"]
                                       and e["settings"][key] == self.settings.get(key))]
        development = {"log": f"benchmarks/devlog/{self.log}.jsonl", "configurations_tried": configurations_tried(entries),
                       "runs": len(entries), "runs_with_these_settings": len(same),
                       "these_settings": "all of them" if key is None else f"the same {key!r} settings",
                       "in_sample": [{"seeds": e["seeds"], "date": e["date"], "result": e["result"]} for e in same]}
        return self.recorder.record({**result, "provenance": {
            "mode": "headline", "seeds": self.seeds, "seed_plan": {"development": _span(self.harness.seeds.development),
                                                                   "headline": _span(self.harness.seeds.headline)},
            "settings_hash": self.settings_hash, "settings": self.settings, "development": development}}, file)
