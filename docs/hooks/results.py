"""Measured numbers on the docs pages, read from benchmarks/results/*.json at every docs build: the one
way a measurement reaches a page (tests/test_docs_numbers.py fails on one typed by hand).

MkDocs runs this file as a hook (mkdocs.yml: `hooks:`). In any page, a macro call in double braces
becomes its text, e.g. `{{ result("sar_study", "settings.sar_sac_fast.projected_study_hours", "h") }}`
-> "5.04 h". The macros (MACROS below), each naming a result file (its stem) and paths into it:

- `result(file, path, form)`: one number of the file, written by `form` (FORMS: "h", "percent", ...;
  "text" for a string, "met" for a target's true or false).
- `seeds(file, path, form)`: a statistic over seeds, from the per-seed values at `path`, by
  motorlab.intervals.across_seeds: the label (IQM or mean, a bootstrap interval or why there is none)
  is always the current rule's, never the text an older run stored beside the values.
- `pooled(file, rates_path, episodes_path)`: a success rate pooled over every seed's episodes, with
  its Wilson interval (motorlab.intervals.pooled_rate).
- `p_better(file, a_path, b_path, a_label, b_label)`: P(A > B) from both sides' per-seed values.
- `steps(file, path)`: steps to a threshold over seeds (motorlab.stats: k of n, the Kaplan–Meier
  median), from the per-seed records at `path` (`steps_of`); `steps_ratio(file, a_path, b_path)`:
  b's median / a's.
- `date(file)`: the day the file's run finished.
- `protocol_hours(file, rate_path, recipe, machines)`: the training hours of a bundled recipe at the
  env steps/s recorded at `rate_path`, on one machine or a Ray cluster of `machines`
  (benchmarks/protocol_time.py: the recipe's own budgets, training only).

A path is the JSON's keys joined by "." (a key that holds a dot itself, like "delayed_tau_0.2s", is
matched whole). A missing file or key, an unknown macro or form fails the build with the page's name.
Macros in code (fenced blocks, `inline code`) are left as they are, so a page can show the syntax.
"""

from __future__ import annotations

import ast
import json
import re
from functools import cache
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "benchmarks" / "results"
# {{ name(args) }}: the args are Python literals (strings, numbers, booleans)
MACRO = re.compile(r"\{\{\s*(\w+)\((.*?)\)\s*\}\}")
FENCE = re.compile(r"^\s*(```|~~~)")
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1")


class MacroError(ValueError):
    """A macro that cannot be rendered: the build stops on it."""


@cache
def load(file: str) -> dict[str, Any]:
    path = RESULTS / f"{file}.json"
    if not path.is_file():
        raise MacroError(f"no result file benchmarks/results/{file}.json")
    return json.loads(path.read_text())


def lookup(data: Any, path: str, file: str = "") -> Any:
    """The value at a dotted path; at each level the longest run of parts that is a key wins (a number: a list's item)."""
    parts = path.split(".")
    while parts:
        if isinstance(data, list) and parts[0].isdigit():  # an item of a list: pareto_front.0.minutes
            if int(parts[0]) >= len(data):
                raise MacroError(f"{file}.json: {path!r} has item {parts[0]} of a list of {len(data)}")
            data, parts = data[int(parts[0])], parts[1:]
            continue
        if not isinstance(data, dict):
            raise MacroError(f"{file}.json: {path!r} goes through a {type(data).__name__}, not an object")
        for n in range(len(parts), 0, -1):
            key = ".".join(parts[:n])
            if key in data:
                data, parts = data[key], parts[n:]
                break
        else:
            raise MacroError(f"{file}.json has no {parts[0]!r} on the path {path!r}")
    return data


def number(v: float) -> str:
    """Three significant figures; whole thousands with separators."""
    return f"{v:,.0f}" if abs(v) >= 1000 else f"{v:.3g}"


# form -> how one number reads on a page (with its unit)
FORMS: dict[str, Callable[[float], str]] = {
    "number": number,
    "count": lambda v: f"{v:,.0f}",
    "percent": lambda v: f"{100 * v:.0f}%",  # a fraction in the file
    "ratio": lambda v: f"{v:.3g}×",
    "ms": lambda v: f"{v:.1f} ms",
    "s": lambda v: f"{number(v)} s",
    "min": lambda v: f"{v:.3g} min",
    "min_of_s": lambda v: f"{v / 60:.3g} min",  # seconds in the file
    "h": lambda v: f"{v:.3g} h",
    "h_of_s": lambda v: f"{v / 3600:.3g} h",
    "per_s": lambda v: f"{number(v)}/s",
    "text": str,
}


def form(name: str) -> Callable[[float], str]:
    if name not in FORMS:
        raise MacroError(f"unknown form {name!r}: give one of {', '.join(FORMS)}, met")
    return FORMS[name]


def _values(file: str, path: str) -> list[float]:
    values = lookup(load(file), path, file)
    if not isinstance(values, list) or not values:
        raise MacroError(f"{file}.json: {path!r} is no list of per-seed values")
    return [float(v) for v in values]


def result(file: str, path: str, how: str = "number") -> str:
    value = lookup(load(file), path, file)
    if how == "text":
        return str(value)
    if how == "met":  # a target's verdict
        if not isinstance(value, bool):
            raise MacroError(f"{file}.json: {path!r} is {value!r}, not true or false")
        return "met" if value else "**not met**"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MacroError(f"{file}.json: {path!r} is {value!r}, not a number")
    return form(how)(value)


# ---- statistics over seeds, computed now from per-seed values (also docs/hooks/benchmark_table.py's)

def across_text(values: list[float], how: str = "number") -> str:
    return _across(tuple(float(v) for v in values), how)


@cache  # a bootstrap per call: the table and the pages ask for the same values more than once
def _across(values: tuple[float, ...], how: str) -> str:
    from motorlab.intervals import across_seeds

    return across_seeds(values).text(form(how))


def p_better_text(a: list[float], b: list[float], a_label: str = "A", b_label: str = "B") -> str:
    return _p_better(tuple(map(float, a)), tuple(map(float, b))).replace("P(A > B)", f"P({a_label} > {b_label})", 1)


@cache
def _p_better(a: tuple[float, ...], b: tuple[float, ...]) -> str:
    from motorlab.intervals import p_better as p

    return p(a, b).text()


def steps_of(value: Any):
    """motorlab.stats' steps to a threshold over seeds, from what a result file holds: per-seed records
    ({steps, budget}), an object with them under "per_seed", or {"steps_to_success": [...], "budget": N}."""
    return _steps(*_seeds_and_budgets(value))


def _seeds_and_budgets(value: Any) -> tuple[tuple[int | None, ...], tuple[int, ...]]:
    if isinstance(value, dict) and "steps_to_success" in value and "budget" in value:
        steps = tuple(value["steps_to_success"])
        return steps, (int(value["budget"]),) * len(steps)
    per_seed = value.get("per_seed") if isinstance(value, dict) else value
    if not isinstance(per_seed, list) or not per_seed or not all(isinstance(s, dict) and "budget" in s
                                                                 for s in per_seed):
        raise MacroError("no per-seed {steps, budget} records there")
    return tuple(s.get("steps") for s in per_seed), tuple(int(s["budget"]) for s in per_seed)


@cache
def _steps(steps: tuple[int | None, ...], budgets: tuple[int, ...]):
    from motorlab.stats import steps_to_threshold

    return steps_to_threshold(list(steps), list(budgets))


def ratio_text(a: Any, b: Any) -> str:
    """b's median steps over a's, from two values `steps_of` reads."""
    return _ratio(_seeds_and_budgets(a), _seeds_and_budgets(b))


@cache
def _ratio(a: tuple, b: tuple) -> str:
    from motorlab.stats import steps_ratio

    return steps_ratio(_steps(*a), _steps(*b)).text


# ---- the macros: a file's stem and paths into it

def seeds(file: str, path: str, how: str = "number") -> str:
    return across_text(_values(file, path), how)


def pooled(file: str, rates_path: str, episodes_path: str) -> str:
    from motorlab.intervals import pooled_rate

    rates, episodes = _values(file, rates_path), [int(e) for e in _values(file, episodes_path)]
    return pooled_rate([round(r * e) for r, e in zip(rates, episodes, strict=True)], episodes).text()


def p_better(file: str, a_path: str, b_path: str, a_label: str = "A", b_label: str = "B") -> str:
    return p_better_text(_values(file, a_path), _values(file, b_path), a_label, b_label)


def _at(file: str, path: str) -> Any:
    value = lookup(load(file), path, file)
    try:
        steps_of(value)
    except MacroError as e:
        raise MacroError(f"{file}.json: {path!r}: {e}") from None
    return value


def steps(file: str, path: str) -> str:
    return steps_of(_at(file, path)).text


def steps_ratio(file: str, a_path: str, b_path: str) -> str:
    return ratio_text(_at(file, a_path), _at(file, b_path))


def date(file: str) -> str:
    day = load(file).get("date")
    if not isinstance(day, str):
        raise MacroError(f"{file}.json records no date")
    return day[:10]


def protocol_hours(file: str, rate_path: str, recipe: str, machines: int) -> str:
    import sys

    if str(ROOT / "benchmarks") not in sys.path:  # protocol_time is a benchmarks/ script's module
        sys.path.insert(0, str(ROOT / "benchmarks"))
    from protocol_time import training_hours

    rate = lookup(load(file), rate_path, file)
    if not isinstance(rate, (int, float)) or not rate > 0:
        raise MacroError(f"{file}.json: {rate_path!r} is {rate!r}, not a rate in env steps/s")
    return form("h")(training_hours(recipe, float(rate), int(machines)))


MACROS: dict[str, Callable[..., str]] = {f.__name__: f for f in (result, seeds, pooled, p_better, steps,
                                                                 steps_ratio, date, protocol_hours)}


def call(name: str, args: str) -> str:
    if name not in MACROS:
        raise MacroError(f"unknown macro {name!r}: give one of {', '.join(MACROS)}")
    try:
        parsed = ast.literal_eval(f"({args},)") if args.strip() else ()
    except (SyntaxError, ValueError) as e:
        raise MacroError(f"{name}({args}): its arguments are not literals ({e})") from None
    try:
        return MACROS[name](*parsed)
    except TypeError as e:
        raise MacroError(f"{name}({args}): {e}") from None


def render_line(line: str) -> str:
    """The macros of one line of prose expanded, code spans left alone."""
    out, last = [], 0
    for span in CODE_SPAN.finditer(line):
        out.append(MACRO.sub(lambda m: call(m[1], m[2]), line[last:span.start()]))
        out.append(span[0])
        last = span.end()
    out.append(MACRO.sub(lambda m: call(m[1], m[2]), line[last:]))
    return "".join(out)


def render(markdown: str) -> str:
    """Every macro of a page expanded, outside fenced code blocks and code spans."""
    lines, fence = [], None
    for line in markdown.split("\n"):
        opened = FENCE.match(line)
        if fence is None and opened:
            fence = opened[1]
        elif fence is not None and line.strip().startswith(fence):
            fence = None
        elif fence is None:
            line = render_line(line)
        lines.append(line)
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs hook
    from mkdocs.exceptions import PluginError

    try:
        return render(markdown)
    except MacroError as e:
        raise PluginError(f"docs/{page.file.src_uri}: {e}") from None


def on_pre_build(config) -> None:  # MkDocs hook: `mkdocs serve` rebuilds read the files again
    load.cache_clear()
