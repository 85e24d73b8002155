"""`motorlab report PATH...`: one self-contained HTML file for run folders and studies.

The file carries everything inline (plots as PNG data URIs, videos as MP4 data URIs,
CSS in the page, no scripts or network assets), so it opens offline and can be mailed:

    findings           a study's few numbers it is about, with seeds, IQM and 95% CI (and, above
                       them, why a quick or demo recipe's budgets or seeds are small)
    study              its figures (each with a caption), then each step's headline numbers,
                       labelled and in their units; the full summary.json one click away
    comparison         training runs side by side, one column per run and seed: their results,
                       then their budgets, with their curves
    runs               per run: headline numbers, every plot and video with its caption, the full
                       summary, the resolved settings (config.toml), a link to its TensorBoard logs
    environment        Python, machine and library versions (the runs' environment.json)

Labels, units and findings come from the results.json files motorlab writes beside each
summary.json (motorlab.report.results); folders without one show their summary.json keys.
"""

from __future__ import annotations

import base64
import csv
import datetime
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from motorlab.errors import MotorlabError, mask_secrets
from motorlab.intervals import across_seeds
from motorlab.provenance import describe
from motorlab.report.plots import figure_caption
from motorlab.report.results import DEMO_LABEL, Finding, Number, StepResults, read_run_results, read_study_results
from motorlab.runs import CONFIG, ENVIRONMENT, SUMMARY, atomic_write_text, is_complete, read_json, wrote_into
from motorlab.stats import steps_of_scores

REPORT = "report.html"
# Headline keys of a comparison, in the order readers scan them; other numbers shared
# by every compared run follow.
COMPARE_FIRST = ("seed", "eval_return_mean", "eval_return_std", "eval_return_min", "eval_success_rate",
                 "train_success_rate_last100", "steps_to_success", "eval_episode_length_mean", "eval_falls",
                 "timesteps", "wall_seconds")
VIDEO_BUDGET = 200 * 2**20  # bytes of video embedded per report; beyond it, videos are linked


def fmt(value: Any) -> str:
    """A number as the report shows it: 4 significant digits, thousands separated."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}"
    if isinstance(value, float):
        return f"{value:,.4g}"
    return "–" if value is None else str(value)


@dataclass
class Cell:
    key: str
    value: Any

    @property
    def text(self) -> str:
        return fmt(self.value)

    @property
    def numeric(self) -> bool:
        return _number(self.value)


@dataclass
class Media:
    name: str
    src: str  # a data: URI, or a relative link when over the video budget
    caption: str = ""  # what it shows (figures: stored in the PNG by save_figure)


@dataclass
class RunView:
    label: str
    path: Path
    summary: dict[str, Any]
    config_text: str
    seed: int | None
    plots: list[Media] = field(default_factory=list)
    videos: list[Media] = field(default_factory=list)
    tensorboard: str | None = None  # relative link from the report
    tensorboard_dir: str | None = None
    environment: dict | None = None
    numbers: list[Number] | None = None  # its headline numbers as shown (results.json), where it has them

    @property
    def cells(self) -> list[Cell]:
        return [Cell(k, v) for k, v in self.summary.items() if _scalar(v)]

    @property
    def lists(self) -> list[tuple[str, str]]:
        return [(k, _describe_list(v)) for k, v in self.summary.items() if isinstance(v, list)]

    @property
    def trained(self) -> bool:
        return (self.path / "metrics.csv").is_file() and "timesteps" in self.summary


@dataclass
class StudyView:
    name: str
    path: Path
    description: str
    steps: list[str]
    columns: list[str]
    rows: list[tuple[str, list[Cell | None]]]
    plots: list[Media]
    runs: list[RunView]
    table_text: str | None
    findings: list[Finding] = field(default_factory=list)
    results: list[StepResults] | None = None  # each step's numbers as shown, where the study wrote them
    linked: set[str] | None = None  # rows whose runs the page shows (None: every row's)
    demo: str | None = None  # why its budgets or seeds are small on purpose (its recipe's `demo`)


def _scalar(v: Any) -> bool:
    return v is None or isinstance(v, (int, float, str, bool))


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _describe_list(v: list) -> str:
    nums = [x for x in v if _number(x)]
    if nums and len(nums) == len(v):
        return f"{len(v)} values, mean {fmt(sum(nums) / len(nums))}, min {fmt(min(nums))}, max {fmt(max(nums))}"
    return ", ".join(Path(x).name if isinstance(x, str) and os.sep in x else fmt(x) for x in v)


def _data_uri(path: Path, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(path.read_bytes()).decode('ascii')}"


class _Collector:
    """Reads run folders into views; embeds media until the video budget is spent."""

    def __init__(self, report_dir: Path):
        self.report_dir = report_dir
        self.video_bytes = 0

    def _rel(self, path: Path) -> str:
        return Path(os.path.relpath(path.resolve(), self.report_dir.resolve())).as_posix()

    def run(self, path: Path, label: str) -> RunView:
        config_path = path / CONFIG
        config_text = config_path.read_text() if config_path.is_file() else ""
        seed = None
        if config_text:
            try:
                seed = tomllib.loads(config_text).get("seed")
            except tomllib.TOMLDecodeError:
                pass
        view = RunView(label=label, path=path, summary=read_json(path / SUMMARY), config_text=config_text, seed=seed)
        results = read_run_results(path)
        view.numbers = results.numbers if results else None
        files = sorted(p for p in path.rglob("*") if p.is_file() and "tensorboard" not in p.relative_to(path).parts)
        view.plots = [_figure(p, p.relative_to(path).as_posix()) for p in files if p.suffix == ".png"]
        captions = _video_captions(path, view.summary)
        for p in (p for p in files if p.suffix == ".mp4"):
            size = p.stat().st_size
            name = p.relative_to(path).as_posix()
            caption = captions.get(p.name, f"An episode filmed by the {label} step ({name})")
            if self.video_bytes + size <= VIDEO_BUDGET:
                self.video_bytes += size
                view.videos.append(Media(name, _data_uri(p, "video/mp4"), caption))
            else:
                view.videos.append(Media(name, self._rel(p), caption))
        if (path / "tensorboard").is_dir():
            view.tensorboard = self._rel(path / "tensorboard") + "/"
            view.tensorboard_dir = str((path / "tensorboard").resolve())
        if (path / ENVIRONMENT).is_file():
            view.environment = read_json(path / ENVIRONMENT)
        return view

    def study(self, path: Path) -> StudyView:
        config = tomllib.loads((path / CONFIG).read_text())
        summary = read_json(path / SUMMARY)
        steps = list(summary.get("steps") or config.get("steps") or [])
        columns: list[str] = []
        per_step: dict[str, dict[str, Any]] = {s: {} for s in steps}
        by_length = sorted(steps, key=len, reverse=True)  # sweep settings may hold dots: "lr=0.001"
        for key, value in summary.items():
            step = next((s for s in by_length if key.startswith(f"{s}.")), None)
            if step is not None and _scalar(value):
                rest = key[len(step) + 1:]
                per_step[step][rest] = value
                if rest not in columns:
                    columns.append(rest)
        rows = [(s, [Cell(f"{s}.{c}", per_step[s][c]) if c in per_step[s] else None for c in columns]) for s in steps]
        plots = [_figure(p, p.name) for p in sorted((path / "plots").glob("*.png"))]
        results = read_study_results(path)
        plots += [_figure(path / f, f) for r in (results.steps if results else []) for f in r.figures
                  if (path / f).is_file()]  # each step's key figures (e.g. MPC's distances)
        runs = []
        for step in steps:
            step_dir = path / step
            if is_complete(step_dir):
                runs.append(self.run(step_dir, step))
            elif step_dir.is_dir():  # several seeds: <step>/seed<k>/
                runs += [self.run(d, f"{step}/{d.name}") for d in sorted(step_dir.iterdir())
                         if is_complete(d)]
        table = path / "table.txt"
        name = config.get("recipe") or (f"sweep of {config['sweep']}" if "sweep" in config else path.name)
        return StudyView(name=name, path=path, description=summary.get("description", ""),
                         steps=steps, columns=columns, rows=rows, plots=plots, runs=runs,
                         table_text=table.read_text() if table.is_file() else None,
                         findings=results.findings if results else [], results=results.steps if results else None,
                         demo=results.demo if results else None)

    def tune(self, path: Path) -> StudyView:
        """A `motorlab tune` folder: the best settings and their numbers on the search's seeds and on
        fresh ones (the findings), the search's plots, one row per trial, and the runs of the best
        trial and of the fresh seeds (the other trials' run folders stay on disk, not in the page)."""
        config = tomllib.loads((path / CONFIG).read_text())
        summary = read_json(path / SUMMARY)
        objective, best = summary.get("objective", ""), summary.get("best_trial")
        with open(path / "trials.csv", newline="") as f:
            trials = list(csv.DictReader(f))
        space = list(config.get("space", {}))
        columns = ["state", *space, "value", "per seed", "env steps", "env steps saved"]
        rows = []
        for t in trials:
            values = [t["state"].lower(), *(_parsed(t.get(k, "")) for k in space), _parsed(t["value"]),
                      _seed_cells(t["seed_values"], t.get("seed_censored", "")),
                      _parsed(t["env_steps"]), _parsed(t["env_steps_saved"])]
            rows.append((f"trial-{t['number']}", [Cell(c, v) for c, v in zip(columns, values)]))
        findings = []
        if best is not None:
            seeds = [f"seed{s}" for s in summary.get("seeds", [])]
            findings.append(_finding(f"{objective}, best trial ({best}) on the search's seeds", f"trial-{best}",
                                     objective, summary["best_value"], seeds, summary.get("best_seed_values") or [],
                                     summary.get("best_seed_censored")))
        if summary.get("fresh_values"):
            findings.append(_finding(f"{objective}, the best settings on fresh seeds", "fresh", objective,
                                     summary.get("fresh_value", summary.get("fresh_iqm")),
                                     [f"seed{s}" for s in summary["fresh_seeds"]],
                                     summary["fresh_values"], summary.get("fresh_censored")))
        runs = []
        for label, folder in ((f"trial-{best}", path / "trials" / str(best)), ("fresh", path / "fresh")):
            if best is not None and folder.is_dir():
                runs += [self.run(d, f"{label}/{d.name}") for d in sorted(folder.glob("seed*")) if is_complete(d)]
        counts = ", ".join(f"{n} {state}" for state, n in (summary.get("n_trials") or {}).items())
        best_params = ", ".join(f"{k}={fmt(v)}" for k, v in (summary.get("best_params") or {}).items())
        description = (f"Optuna search ({config.get('sampler', 'tpe')} sampler, {config.get('pruner', 'median')} "
                       f"pruning), {summary.get('direction', '')} {objective}: each trial is the "
                       f"{summary.get('statistic', 'IQM')} over seeds "
                       f"{', '.join(map(str, summary.get('seeds', [])))}. Trials: {counts}. "
                       + (f"Best: trial {best}, {best_params}. best.toml holds it as a preset file "
                          "(motorlab train --preset-file best.toml). " if best is not None else "")
                       + f"Pruning saved {fmt(summary.get('env_steps_saved_by_pruning', 0))} env steps "
                         f"of {fmt(summary.get('env_steps_run', 0))} run.")
        table = path / "table.txt"
        return StudyView(name=f"tune of {config.get('tune', path.name)}", path=path, description=description,
                         steps=[r[0] for r in rows], columns=columns, rows=rows,
                         plots=[_figure(p, p.name) for p in sorted((path / "plots").glob("*.png"))], runs=runs,
                         table_text=table.read_text() if table.is_file() else None, findings=findings,
                         linked={r.label.split("/")[0] for r in runs})

def _figure(path: Path, name: str) -> Media:
    """A PNG with its caption (the file name where it carries none: written by something else)."""
    return Media(name, _data_uri(path, "image/png"), figure_caption(path) or name)


def _video_captions(path: Path, summary: dict[str, Any]) -> dict[str, str]:
    """Captions of a video step's episodes (file name -> "episode 0, return 812.3")."""
    videos, returns = summary.get("videos"), summary.get("returns")
    if not isinstance(videos, list) or not isinstance(returns, list) or len(videos) != len(returns):
        return {}
    return {Path(v).name: f"Episode {i} of the policy, filmed: return {fmt(r)}"
            for i, (v, r) in enumerate(zip(videos, returns))}


def _finding(label: str, step: str, key: str, value: float, seeds: list[str], values: list[float],
             censored: list[bool] | None = None) -> Finding:
    """A tuning number over seeds (the search's value, or the fresh seeds'), each seed's value, and
    what the seeds give together (motorlab.intervals: a 95% CI from 5 seeds, the seeds' range below).
    Steps to success: k of n solved and their Kaplan-Meier median, each with its interval named in the
    text, an unsolved seed shown as "> budget"."""
    censored = censored or [False] * len(values)
    together = {}
    steps = key.rpartition(".")[2] == "steps_to_success"
    if steps and values:
        reached = steps_of_scores(list(zip(values, censored)))
        together = {"aggregate": reached.text, "ci": None, "ci_method": "unsolved seeds censored at their budgets"}
    elif len(values) > 1:
        summary = across_seeds(values)
        shown = summary.interval  # the 95% CI from 5 seeds, else the seeds' range, named by ci_method
        together = {"aggregate": f"{summary.statistic} {fmt(summary.value)}",
                    "ci": f"[{fmt(shown[0])}, {fmt(shown[1])}]" if shown else None, "ci_method": summary.method}
    text = f"restricted mean {fmt(value)}" if steps else fmt(value)
    return Finding(label=label, step=step, key=key, text=text, value=value, seeds=seeds,
                   values=[f"> {fmt(v)}" if c else fmt(v) for v, c in zip(values, censored)], **together)


def _seed_cells(values: str, censored: str) -> str:
    """trials.csv's per-seed numbers as people read them: an unsolved seed's "> budget"."""
    flags = [c == "1" for c in censored.split()] or [False] * len(values.split())
    return " ".join(f">{v}" if c else v for v, c in zip(values.split(), flags))


def _parsed(text: str) -> Any:
    """A trials.csv cell as a number where it is one."""
    try:
        return int(text)
    except ValueError:
        try:
            return float(text)
        except ValueError:
            return text or None


def _kind(path: Path) -> str | None:
    """"study", "sweep" or "tune" for those folders (their config.toml says which), else None."""
    try:
        config = tomllib.loads((path / CONFIG).read_text())
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return None
    return next((k for k, key in (("study", "recipe"), ("sweep", "sweep"), ("tune", "tune")) if key in config), None)


def _check_path(path: Path) -> Path:
    if not path.exists():
        raise MotorlabError(f"{path} does not exist; give run folders or study folders (motorlab run --out DIR).")
    if not path.is_dir() or not is_complete(path):
        raise MotorlabError(f"{path} is not a finished run or study folder (no {SUMMARY}); "
                            "give folders written by motorlab train/evaluate/run.")
    return path


@dataclass
class Comparison:
    """Training runs side by side: rows of results (label, key), then rows of setup (budgets,
    seeds, time), then every other number they share (in the full table, one click away)."""

    runs: list[RunView]
    results: list[tuple[str, str]]
    setup: list[tuple[str, str]]
    rest: list[str]

    def cell(self, run: RunView, key: str) -> tuple[Any, str]:
        """(value, text) of `key` in a run: its shown number where it has one, else its summary's."""
        if key == "seed":
            return run.seed, fmt(run.seed)
        shown = next((n for n in run.numbers or [] if n.key == key), None)
        return (shown.value, shown.text) if shown else (run.summary.get(key), fmt(run.summary.get(key)))


def _comparison(runs: list[RunView]) -> Comparison | None:
    """Training runs to show side by side, and what to compare them on."""
    trained = [r for r in runs if r.trained]
    if len(trained) < 2:
        return None
    shared = [k for k in trained[0].summary if all(_number(r.summary.get(k)) for r in trained)]
    if all(r.numbers is not None for r in trained):
        numbers = {n.key: n for r in trained for n in r.numbers}  # in each run's order; union of what they show
        results = [(n.label, k) for k, n in numbers.items() if not n.setup]
        setup = [("seed", "seed")] + [(n.label, k) for k, n in numbers.items() if n.setup]
    else:  # older folders: the keys readers scan first
        results = [(k, k) for k in COMPARE_FIRST if k in shared and k not in ("timesteps", "wall_seconds")]
        setup = [("seed", "seed")] + [(k, k) for k in ("timesteps", "wall_seconds") if k in shared]
    return Comparison(trained, results, setup, [k for k in shared if k != "seed"])


def _environments(runs: list[RunView]) -> list[tuple[dict, list[str]]]:
    """Distinct environments with the runs that used each (report-time one if no run recorded any)."""
    distinct: list[tuple[dict, list[str]]] = []
    for r in runs:
        if r.environment is None:
            continue
        for env, labels in distinct:
            if env == r.environment:
                labels.append(r.label)
                break
        else:
            distinct.append((r.environment, [r.label]))
    return distinct or [(describe(), ["(report time: the runs recorded none)"])]


def build_report(paths: list[Path], out: Path | None = None) -> Path:
    """Write the report for run and study folders `paths`; returns its path
    (default: report.html inside the first path).

    Raises:
        MotorlabError: a path that is not a finished run or study folder.
    """
    import jinja2

    if not paths:
        raise MotorlabError("give at least one run or study folder.")
    paths = [_check_path(Path(p)) for p in paths]
    out = Path(out) if out is not None else paths[0] / REPORT
    if out.exists() and out.is_dir():
        raise MotorlabError(f"--out {out} is a folder; give a file path such as {out / REPORT}.")
    out.parent.mkdir(parents=True, exist_ok=True)
    collector = _Collector(out.parent)
    studies, runs = [], []
    for p in paths:
        if _kind(p) == "tune":
            studies.append(collector.tune(p))
        elif _kind(p) is not None:
            studies.append(collector.study(p))
        else:
            runs.append(collector.run(p, p.name))
    all_runs = runs + [r for s in studies for r in s.runs]
    comparison = _comparison(all_runs)
    env = jinja2.Environment(loader=jinja2.PackageLoader("motorlab.report", "templates"),
                             # report.html.j2: select_autoescape() alone matches .html, not .html.j2 (text was inserted raw)
                             autoescape=jinja2.select_autoescape(["html", "htm", "xml", "html.j2"]), undefined=jinja2.StrictUndefined,
                             finalize=mask_secrets)  # every value the page shows, before escaping: no credential
    html = env.get_template("report.html.j2").render(
        title=" · ".join(s.name for s in studies) or " · ".join(r.label for r in runs),
        created=datetime.datetime.now().strftime("%Y-%m-%d %H:%M"), studies=studies, runs=runs,
        comparison=comparison, environments=_environments(all_runs),
        motorlab_version=describe()["packages"]["motorlab"], fmt=fmt, demo_label=DEMO_LABEL)
    atomic_write_text(out, html)
    wrote_into(out)  # into a finished run's folder (by default): its marker lists it
    return out
