"""The benchmarks page's table of recorded results, generated from benchmarks/results/*.json at every
docs build, so no number on it is typed by hand.

MkDocs runs this file as a hook (mkdocs.yml: `hooks:`): in docs/benchmarks.md the line
`<!-- benchmark-results -->` becomes one row per result file (a benchmark of several envs writes one
file per env, e.g. mbrl-pendulum.json), naming the file, its date and commit, and its headline
facts, each read from the file; a benchmark script with no file reads "not yet run".

tests/test_benchmark_table.py checks every fact in the table against its JSON.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PLACEHOLDER = "<!-- benchmark-results -->"
PAGE = "benchmarks.md"
ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
# modules in benchmarks/ that the benchmarks import: not benchmarks of their own
HELPERS = frozenset({"provenance", "mbrl_body", "user_reacher_reward"})


@dataclass(frozen=True)
class Fact:
    """One number of a result file, as the table shows it: its label, where it sits in the JSON (a
    path of keys), and how it is written."""

    label: str
    path: tuple[str, ...]
    form: str  # "count", "ms", "ratio", "text", "met"

    def value(self, data: dict[str, Any]) -> Any:
        for key in self.path:
            data = data[key]
        return data

    def text(self, data: dict[str, Any]) -> str:
        return f"{self.label} {show(self.value(data), self.form)}"


def show(value: Any, form: str) -> str:
    if value is None:
        return "–"
    if form == "met":
        return "yes" if value else "**no**"
    if form == "ms":
        return f"{value:.1f} ms"
    if form == "ratio":
        return f"{value:.3g}x"
    if form == "count":
        return f"{value:,}"
    return str(value)


def facts(benchmark: str, data: dict[str, Any]) -> list[Fact]:
    """The headline facts of a result file, by the benchmark that wrote it."""
    if benchmark == "mbrl":
        return [Fact("loop:", ("loop", "steps_to_threshold", "text"), "text"),
                Fact("target", ("targets", "loop_seeds", "target"), "text"),
                Fact("target met:", ("targets", "loop_seeds", "met"), "met"),
                Fact("SAC:", ("sac", "steps_to_threshold", "text"), "text"),
                Fact("SAC / loop", ("ratio_sac_over_loop", "text"), "text"),
                Fact("plan per control step:", ("targets", "plan_ms", "median"), "ms")]
    if benchmark == "plan_latency":
        return [*(Fact(f"{env}:", ("envs", env, "ms_median"), "ms") for env in data["envs"]),
                Fact("every env under 50 ms:", ("all_met",), "met")]
    if benchmark == "mpc_reward":
        return [Fact(f"{group}: learned reward / exact", ("groups", group, "ratios", "learned_over_builtin"), "ratio")
                for group in data["groups"]] + \
               [Fact(f"{group}: user's reward / bundled", ("groups", group, "ratios", "user_over_builtin"), "ratio")
                for group in data["groups"]]
    return target_facts(data)


def target_facts(data: dict[str, Any]) -> list[Fact]:
    """Any other benchmark: whether each of its targets is met, wherever its file says so."""
    if isinstance(data.get("met"), dict):
        return [Fact(f"{k} met:", ("met", k), "met") for k in data["met"]]
    if isinstance(data.get("targets"), dict) and all(isinstance(v, dict) and "met" in v for v in data["targets"].values()):
        return [Fact(f"{k} met:", ("targets", k, "met"), "met") for k in data["targets"]]
    for key in ("meets_target", "meets_scaled_targets", "meets_targets", "all_met"):
        if isinstance(data.get(key), bool):
            return [Fact("target met:", (key,), "met")]
    return []


def scripts() -> list[str]:
    return sorted(p.stem for p in BENCHMARKS.glob("*.py") if p.stem not in HELPERS)


def result_files(script: str, results: Path) -> list[Path]:
    """benchmarks/results/<script>.json, or <script>-<env>.json for a benchmark of several envs."""
    return sorted(p for p in results.glob("*.json") if p.stem == script or p.stem.startswith(f"{script}-"))


def dated(path: Path, data: dict[str, Any]) -> str:
    """The run's date: the file's own, else the day its last version was committed."""
    if isinstance(data.get("date"), str):
        return data["date"][:10]
    try:
        day = subprocess.run(["git", "log", "-1", "--format=%cs", "--", str(path)], cwd=ROOT, capture_output=True,
                             text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        day = ""
    return day or "undated"


def rows(results: Path = BENCHMARKS / "results") -> list[tuple[str, str, str, str]]:
    """(script, file, date and commit, facts) per result file; a script without one: "not yet run"."""
    out = []
    for script in scripts():
        files = result_files(script, results)
        if not files:
            out.append((f"`{script}.py`", "–", "–", "not yet run"))
        for path in files:
            data = json.loads(path.read_text())
            commit = (data.get("git") or {}).get("commit") or ""
            when = dated(path, data) + (f", `{commit[:7]}`" if commit else "")
            shown = "; ".join(f.text(data) for f in facts(data.get("benchmark", script), data))
            if data.get("quick"):
                shown = f"(a `--quick` smoke run) {shown}"
            out.append((f"`{script}.py`", f"`{path.name}`", when, shown or "(no headline facts named for it yet)"))
    return out


def render(results: Path = BENCHMARKS / "results") -> str:
    lines = ["| benchmark | result file | run on | recorded |", "|---|---|---|---|"]
    lines += [f"| {' | '.join(row)} |" for row in rows(results)]
    return "\n".join(lines) + "\n"


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs hook
    if page.file.src_uri != PAGE:
        return markdown
    if PLACEHOLDER not in markdown:
        raise RuntimeError(f"docs/{PAGE} lost its {PLACEHOLDER} line")
    return markdown.replace(PLACEHOLDER, render())
