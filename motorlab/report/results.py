"""What a run or a study found, as people read it: labelled numbers with units, and a study's findings.

A step kind names its headline numbers as `Metric`s (summary key, label, unit). A finished run
gets `results.json` beside its summary.json: those numbers formatted (`Number`). A study's
`results.json` holds its findings (the few numbers the recipe is about, with seeds and intervals)
and each step's numbers. `table.txt` and `report.html` show these; summary.json keeps every
number for programs.

These files are written by the code that knows the kinds (motorlab.stepkind, the studies
runner) and read by the report, which knows no kind: a report of old folders without them
falls back to their summary.json.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

from motorlab.runs import atomic_write_text

RESULTS = "results.json"
# What a study's findings say above them when its recipe is a demonstration (its `demo` line follows)
DEMO_LABEL = "A demonstration, not evidence"

Form = Literal["number", "return", "percent", "steps", "count", "mm", "ms", "s", "text"]


def show(value: Any, form: Form = "number") -> str:
    """A value as a reader expects it: 20% (not 0.2), 12,288 steps, 4.2 mm, 3.1 ms."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if form == "text" or isinstance(value, str):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    match form:
        case "percent":
            return f"{value:.0%}" if value in (0, 1) or abs(value - round(value, 2)) < 5e-4 else f"{value:.1%}"
        case "steps":
            return f"{value / 1e6:.3g}M steps" if abs(value) >= 1e6 else f"{value:,.0f} steps"
        case "count":
            return f"{value:,.0f}"
        case "return":
            return f"{value:,.1f}"
        case "mm":
            return f"{value:,.1f} mm"
        case "ms":
            return f"{value:,.2f} ms" if abs(value) < 10 else f"{value:,.0f} ms"
        case "s":
            return f"{value:,.1f} s"
    if isinstance(value, int):
        return f"{value:,}"
    return f"{value:,.4g}" if abs(value) >= 1e-3 or value == 0 else f"{value:.2e}"


def fixed(value: Any, spec: str) -> str:
    """`value` in a format spec (".1f", ".0%") for a printout's table cell; "–" where there is no
    number (a success rate where the env defines no success, a mean of no finite return)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return format(value, spec)


@dataclass(frozen=True)
class Metric:
    """One headline number of a step kind.

    Attributes:
        key: its key in the step's headline (and "<step>.<key>" in a study's summary.json).
        label: what a reader calls it ("success", "final distance").
        form: how it is shown (unit and format, see `show`).
        scale: multiplies the value before it is shown (metres -> mm: 1000).
        spread: the key of its ± (standard deviation), shown after it.
        of: the key of the total it counts out of ("falls 2/10").
        setup: a budget or setting (seeds, env steps, seconds), not a result: reports show it apart.
    """

    key: str
    label: str
    form: Form = "number"
    scale: float = 1.0
    spread: str | None = None
    of: str | None = None
    setup: bool = False

    def text(self, value: Any, values: dict[str, Any]) -> str:
        scaled = value * self.scale if self.scale != 1 and _numeric(value) else value
        out = show(scaled, self.form)
        spread = values.get(self.spread) if self.spread else None
        if _numeric(spread) and math.isfinite(spread) and _numeric(value) and math.isfinite(value):
            # "12.3 ± 2.0 mm": the unit once, at the end; never "inf ± nan"
            number, _, unit = out.partition(" ")
            spread = show(values[self.spread] * self.scale, self.form).partition(" ")[0]
            out = f"{number} ± {spread}" + (f" {unit}" if unit else "")
        if self.of and values.get(self.of) is not None:
            out = f"{out}/{show(values[self.of], 'count')}"
        return out

    def interval(self, low: Any, high: Any) -> str:
        """A confidence interval in this metric's unit and format: "[28.5, 32.0]"."""
        return f"[{self.text(low, {})}, {self.text(high, {})}]"

    def number(self, values: dict[str, Any], label: str | None = None) -> Number | None:
        """The number as shown, from a headline (None where the headline has no value for it); an
        IQM's 95% CI follows it where the headline holds "<key>_ci_low" and "<key>_ci_high"."""
        value = values.get(self.key)
        if value is None:
            return None
        text = self.text(value, values)
        low, high = values.get(f"{self.key}_ci_low"), values.get(f"{self.key}_ci_high")
        if low is not None and high is not None:
            text = f"{text} {self.interval(low, high)}"
        return Number(self.key, label or self.label, value, text, self.setup)


def _numeric(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


@dataclass(frozen=True)
class Number:
    """A headline number as shown: `text` is `value` in its unit and format."""

    key: str
    label: str
    value: Any
    text: str
    setup: bool = False

    @property
    def numeric(self) -> bool:
        return _numeric(self.value)


@dataclass(frozen=True)
class RunResults:
    """results.json of a run folder: the kind that wrote it and its headline numbers."""

    kind: str
    numbers: list[Number]


@dataclass(frozen=True)
class StepResults:
    """One step of a study: what it did and its numbers (several seeds: aggregated)."""

    step: str
    kind: str
    what: str
    numbers: list[Number]
    note: str = ""
    figures: list[str] = field(default_factory=list)  # its key figures, relative to the study folder


@dataclass(frozen=True)
class Finding:
    """One number a study is about: the value (a single run's, or the mean over seeds) and, with
    several seeds, each seed's value and what they give together (motorlab.intervals): "IQM 61%"
    (4 seeds or more) or "mean 20%", a 95% interval only where the seeds allow one (3 or more), and
    `ci_method`, what the interval is or why there is none ("n = 2: too few seeds for an interval").
    A success rate also gets `pooled`: its episodes pooled over the seeds, with a Wilson interval."""

    label: str
    step: str
    key: str
    text: str
    value: Any
    seeds: list[str] = field(default_factory=list)
    values: list[Any] = field(default_factory=list)
    aggregate: str | None = None
    ci: str | None = None
    ci_method: str | None = None
    # a success rate: every episode of every seed pooled, with its Wilson interval (and what it is)
    pooled: str | None = None

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Finding:
        """A results.json finding. An older file's "iqm" and "ci" are dropped: they were written
        for any number of seeds, so from 1-2 seeds their "CI" was the seeds' own range or a point."""
        return cls(**{k: v for k, v in data.items() if k not in ("iqm", "ci") or "ci_method" in data})

    @property
    def spread_text(self) -> str:
        """The seeds' values, e.g. "seed0 80%, seed1 60%"."""
        return ", ".join(f"{s} {v}" for s, v in zip(self.seeds, self.values))


@dataclass(frozen=True)
class StudyResults:
    """results.json of a study folder. `demo`: why its recipe's budgets or seeds are small on
    purpose (a quick or demo recipe), shown with the findings; None for a full study (and in files
    written before it existed)."""

    findings: list[Finding]
    steps: list[StepResults]
    demo: str | None = None


def _numbers(rows: list[dict[str, Any]]) -> list[Number]:
    return [Number(**r) for r in rows]


def write_run_results(run_dir: Path, results: RunResults) -> None:
    atomic_write_text(Path(run_dir) / RESULTS, json.dumps(asdict(results), indent=1, default=str) + "\n")


def write_study_results(study_dir: Path, results: StudyResults) -> None:
    atomic_write_text(Path(study_dir) / RESULTS, json.dumps(asdict(results), indent=1, default=str) + "\n")


def _load(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def read_run_results(run_dir: Path) -> RunResults | None:
    """A run's results.json (None where it has none: older folders, or one that does not parse)."""
    data = _load(Path(run_dir) / RESULTS)
    try:
        return RunResults(data["kind"], _numbers(data["numbers"])) if data else None
    except (KeyError, TypeError):
        return None


def read_study_results(study_dir: Path) -> StudyResults | None:
    data = _load(Path(study_dir) / RESULTS)
    try:
        return StudyResults([Finding.from_json(f) for f in data["findings"]],
                            [StepResults(**{**s, "numbers": _numbers(s["numbers"])}) for s in data["steps"]],
                            data["demo"] if isinstance(data.get("demo"), str) else None) if data else None
    except (KeyError, TypeError):
        return None


def results_text(numbers: list[Number], setup: bool = False) -> str:
    """Numbers on one line, as table.txt shows them: "return 950.0 ± 12.3, success 80%"."""
    return ", ".join(f"{n.label} {n.text}" for n in numbers if n.setup == setup)
