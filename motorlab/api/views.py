"""What the Python API returns: a view of a run folder that reads what the CLI wrote.

Every function of `motorlab.api` writes the same run folder as its command and returns one of
these. They hold only the folder's path and read its files when asked, so a `Result` is as
good as the folder: `motorlab.load("runs/ppo")` gives the same object a week later.

- `Result`: any step's folder (summary.json, config.toml, results.json, plots/, videos/).
- `Run` (motorlab.api.policies): a training run, plus its policy, evaluation, videos and plots.
- `Study`, `Sweep`, `Tune`: the folders of `run_recipe`, `sweep` and `tune`.

In Jupyter each shows its headline numbers as a table and its plots inline (`_repr_html_`).
"""

from __future__ import annotations

import base64
import html
import tomllib
from collections.abc import Callable
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from motorlab.api.checks import api_function
from motorlab.errors import MotorlabError
from motorlab.kinds.train import TRAIN
from motorlab.report.results import DEMO_LABEL, Number, read_run_results, read_study_results
from motorlab.runs import CONFIG, SUMMARY, is_complete, read_json

if TYPE_CHECKING:
    from motorlab.policies import Policy

# The classes folders of a kind open as (the train kind's: motorlab.api.policies.Run, which adds itself)
FOLDER_TYPES: dict[str, type[Result]] = {}
MAX_INLINE_FIGURES = 6  # a notebook cell shows this many plots; report() has them all
MAX_INLINE_VIDEO_BYTES = 8 << 20  # and its first video, where it is small enough to keep in the notebook


class Result:
    """One finished run folder of any step: its summary, settings, numbers and files.

    Attributes:
        path: the run folder.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)

    @property
    def name(self) -> str:
        return self.path.name

    @cached_property
    def summary(self) -> dict[str, Any]:
        """summary.json: every headline number of the run, flat keys."""
        return read_json(self.path / SUMMARY)

    @cached_property
    def config(self) -> dict[str, Any]:
        """config.toml: the resolved settings the run used (run it again with `--config`)."""
        try:
            return tomllib.loads((self.path / CONFIG).read_text())
        except FileNotFoundError:
            return {}

    @property
    def kind(self) -> str | None:
        """The step kind that wrote the folder ("train", "evaluate", "fit", ...), from results.json."""
        results = read_run_results(self.path)
        return results.kind if results else None

    @property
    def numbers(self) -> list[Number]:
        """The headline numbers as people read them (label, value, text with its unit)."""
        results = read_run_results(self.path)
        return results.numbers if results else []

    def __getitem__(self, key: str) -> Any:
        """A summary number: `result["return_mean"]`."""
        return self.summary[key]

    @property
    def figures(self) -> list[Path]:
        """The PNG figures of the folder (plots/*.png, and any at its top level)."""
        return sorted(self.path.glob("plots/*.png")) + sorted(self.path.glob("*.png"))

    @property
    def videos(self) -> list[Path]:
        """The MP4 videos of the folder (videos/*.mp4)."""
        return sorted(self.path.glob("videos/*.mp4")) + sorted(self.path.glob("*.mp4"))

    @api_function
    def report(self, out: str | Path | None = None) -> Path:
        """Write the self-contained HTML report of this folder (`motorlab report`); returns its path."""
        from motorlab.report.html import build_report

        return build_report([self.path], Path(out) if out is not None else None)

    # ---- display -----------------------------------------------------------------------

    def _rows(self) -> list[tuple[str, str]]:
        """(label, text) rows of the headline table."""
        if numbers := [n for n in self.numbers if not n.setup] or self.numbers:
            return [(n.label, n.text) for n in numbers]
        return [(k, _short(v)) for k, v in self.summary.items() if _scalar(v)][:12]

    def _title(self) -> str:
        return f"{self.kind or 'run'}: {self.path}"

    def __repr__(self) -> str:
        shown = ", ".join(f"{label} {text}" for label, text in self._rows()[:4])
        return f"{type(self).__name__}({str(self.path)!r}{': ' + shown if shown else ''})"

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr><th style='text-align:left'>{html.escape(label)}</th>"
                       f"<td style='text-align:right'>{html.escape(text)}</td></tr>" for label, text in self._rows())
        figures = "".join(f"<img src='data:image/png;base64,{base64.b64encode(p.read_bytes()).decode()}' "
                          f"title='{html.escape(p.name)}' style='max-width:32%;margin:2px'>"
                          for p in self.figures[:MAX_INLINE_FIGURES])
        videos = [p for p in self.videos[:1] if p.stat().st_size <= MAX_INLINE_VIDEO_BYTES]
        video = "".join(f"<br><video controls loop muted playsinline style='max-width:48%' title='{html.escape(p.name)}' "
                        f"src='data:video/mp4;base64,{base64.b64encode(p.read_bytes()).decode()}'></video>"
                        for p in videos)
        return f"<div><b>{html.escape(self._title())}</b><table>{rows}</table>{figures}{video}</div>"


class PolicyFunction:
    """A run's policy as a function: one observation in, one action out (or a batch: rows)."""

    def __init__(self, policy: Policy):
        self.inner = policy
        self._rows: int | None = None

    def reset(self) -> None:
        """Start a new episode (stateful controllers such as PID forget their past)."""
        self._rows = None

    def __call__(self, obs: Any) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        if self._rows != len(batch):
            self.inner.reset(len(batch))
            self._rows = len(batch)
        action = self.inner.act(batch)
        return action[0] if single else action


class Study(Result):
    """A study's folder (`motorlab.run_recipe`, `motorlab run`): its table, findings and steps."""

    label = "study"  # its kind
    config_key = "recipe"  # the config.toml key that names what it ran
    findings = True  # its headline rows are the study's findings (sweeps, tunes: their summary)

    def _title(self) -> str:
        return f"{self.label} {self.config.get(self.config_key, '')}: {self.path}"

    @property
    def kind(self) -> str | None:
        return self.label

    @property
    def table(self) -> str:
        """table.txt: every step's numbers, as the command printed them."""
        path = self.path / "table.txt"
        return path.read_text() if path.is_file() else ""

    @property
    def steps(self) -> dict[str, Result | list[Result]]:
        """Each step's run folder by step name (a step trained for several seeds: one per seed)."""
        found: dict[str, Result | list[Result]] = {}
        for name in self.config.get("steps", []):
            folder = self.path / name
            if is_complete(folder):
                found[name] = load(folder)
            elif seeds := sorted(p for p in folder.glob("seed*") if is_complete(p)):
                found[name] = [load(p) for p in seeds]
        return found

    @property
    def demo(self) -> str | None:
        """Why its budgets or seeds are small on purpose (a quick or demo recipe's `demo`), else None."""
        results = read_study_results(self.path) if self.findings else None
        return results.demo if results else None

    def _rows(self) -> list[tuple[str, str]]:
        results = read_study_results(self.path) if self.findings else None
        if results is None:
            return super()._rows()
        demo = [(DEMO_LABEL, results.demo)] if results.demo else []  # first: a reader sees it before the numbers
        return demo + [(f"{f.label} ({f.step})", f.text + (f"  {_over_seeds(f)}" if f.aggregate else "")
                        + (f"  episodes: {f.pooled}" if f.pooled else "")) for f in results.findings]

    def _repr_html_(self) -> str:
        table = html.escape(self.table)
        return super()._repr_html_().replace("</table>", f"</table><pre>{table}</pre>", 1)


class Sweep(Study):
    """A sweep's folder (`motorlab.sweep`): the aggregate over seeds and settings."""

    label = config_key = "sweep"
    findings = False

    @property
    def aggregate(self) -> dict[str, Any]:
        """aggregate.json: rliable's IQMs with 95% CIs per setting, and probabilities of improvement."""
        return read_json(self.path / "aggregate.json")


class Tune(Study):
    """A search's folder (`motorlab.tune`): the best settings and every trial."""

    label = config_key = "tune"
    findings = False

    @property
    def best(self) -> dict[str, Any]:
        """best.toml: the best trial's settings (`motorlab train ... --preset-file OUT/best.toml`)."""
        path = self.path / "best.toml"
        return tomllib.loads(path.read_text()) if path.is_file() else {}

    @property
    def trials(self) -> list[dict[str, str]]:
        """trials.csv, one dict per trial (number, state, value, per-seed values, settings)."""
        import csv

        path = self.path / "trials.csv"
        if not path.is_file():
            return []
        with path.open(newline="") as f:
            return list(csv.DictReader(f))


@api_function
def load(path: str | Path) -> Result:
    """Open a finished run, study, sweep or tune folder as the object the API returned for it.

    Raises:
        MotorlabError: the folder does not exist or has not finished (no summary.json).
    """
    folder = Path(path)
    if not is_complete(folder):
        if not folder.exists():
            raise MotorlabError(f"{folder} does not exist; give a folder written by motorlab (its --out).")
        raise MotorlabError(f"{folder} has no {SUMMARY}: it is not a motorlab run folder, or it did not finish; "
                            "run the step again (the same --out resumes a study).")
    config = Result(folder).config
    for cls in (Study, Sweep, Tune):
        if cls.config_key in config:
            return cls(folder)
    kind = Result(folder).kind
    if kind is None and (folder / "policy.json").is_file() and "algo" in config:  # a training run from before results.json
        kind = TRAIN.name
    return FOLDER_TYPES.get(kind, Result)(folder)


def as_path(value: str | Path | Result, provides: Callable[[str], str | None] | None = None) -> str:
    """A step's input as the CLI takes it: a path, or a `Result` (its folder, or the file in it that
    its kind provides, e.g. a fit's sar.npz)."""
    if isinstance(value, Result):
        file = provides(value.kind) if provides and value.kind else None
        return str(value.path / file) if file else str(value.path)
    return str(value)


def _scalar(value: Any) -> bool:
    return isinstance(value, (int, float, str, bool)) or value is None


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:,.4g}"
    return str(value)


def _over_seeds(f) -> str:
    """E.g. "IQM 61% [52%, 70%] (95% stratified-bootstrap CI over 5 seeds)"."""
    return f"{f.aggregate}{' ' + f.ci if f.ci else ''} ({f.ci_method})"
