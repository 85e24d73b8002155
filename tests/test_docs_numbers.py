"""No measured number typed by hand in the docs (docs/**/*.md), README.md or a recipe's comments.

The rule. A number with a unit -- h, hours, min, minutes, s, seconds, ms, days, a rate "/s" (774/s,
775 env steps/s), a ratio written "x" or "×" against the number (12.7×, 1.7x) or before a word
("1.48 x the median"), or % -- is a measurement unless it is one of:

- generated: inside a macro call `{{ ... }}` (docs/hooks/results.py renders it from
  benchmarks/results/*.json at every build);
- code: inside an inline code span or a fenced code block (a command, a setting, a value to type);
  a comment in a fenced block (after "#") is prose and is checked;
- a confidence level: "95% CI", "95% interval", "95% band", "95% Wilson", "95% bootstrap", ...;
- a definition (a budget, a threshold, a setting, a target, an example) listed in a marker on its
  line: `<!-- def: 0.2 s, 50 ms -->` (Markdown); only the figures it lists are allowed, so a
  measurement beside them on the same line is still found;
- on a page marked `<!-- numbers: history -->` (the changelog: each entry keeps the figures of its
  day; the current ones are on the benchmarks page).

In a recipe (TOML) every comment line is prose; its definitions go in code spans (the settings
themselves are TOML, not comments). A product "25 x 80" or "5 × 1.5M" (a number after the x) is
arithmetic, not a ratio. Counts of env steps (1.5M, 200k) are budgets, so k and M are no unit.

Paragraphs are read whole (a figure and its unit, or a code span, may run over a line break); each
finding is reported as file:line and the figure; fix it by generating it with a macro,
removing it, or marking it as a definition. docs/benchmarks.md states the rule for readers.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.helpers import docs_hook

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.fast




results = docs_hook("results")

NUM = r"\d[\d,]*(?:\.\d+)?"
SPAN = rf"[~≈]?{NUM}(?:\s?(?:–|-|to)\s?{NUM})?"  # one figure or a range: 58-72, ~1.9–3.6
UNIT = r"(?:hours?|h|minutes?|min|seconds?|secs?|s|ms|days?|%|(?:[A-Za-z][A-Za-z \n]{0,24})?/s)"
# a unit ends the word: "5 seeds" and "2 hands" are no durations; a rate's "/s" ends at a non-letter
WITH_UNIT = re.compile(rf"(?<![\w.,/]){SPAN}\s?{UNIT}(?![\w/])")
# a ratio: x or × against the number, or spaced and followed by a word (a number or code after it: a product)
RATIO = re.compile(rf"(?<![\w.,/]){SPAN}(?:[x×](?![\w])|\s[x×](?=\s+[^\W\d]))")
CONFIDENCE = re.compile(r"\d+%\s+(?:stratified[- ])?(?:CI|confidence|interval|band|Wilson|bootstrap|percentile)")
DEF = re.compile(r"<!--\s*def:\s*(.*?)\s*-->")
HISTORY = "<!-- numbers: history -->"
CODE = "\x00"  # where a code span was: an operand, so "3 × `--report-every`" is a product


@dataclass(frozen=True)
class Finding:
    file: str
    line: int
    figure: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.figure}"


def _norm(figure: str) -> str:
    return re.sub(r"[\s~≈]", "", figure)


def _mask(m: re.Match, lead: str = " ") -> str:
    """A span blanked out, its line breaks kept (so an offset still tells the line)."""
    return lead + "".join("\n" if c == "\n" else " " for c in m[0][1:])


def block_figures(block: list[tuple[int, str]]) -> list[tuple[int, str]]:
    """(line number, figure) of the numbers with a unit in a block of consecutive lines of prose (a
    paragraph: a figure and its unit, or a code span, may run over a line break), macros, code spans
    and confidence levels out, minus the definitions each line's marker lists."""
    allowed = {n: {_norm(f) for marker in DEF.findall(line) for f in re.split(r"[,;]\s+", marker)}  # 1,000 is one
               for n, line in block}
    text = "\n".join(DEF.sub("", line).strip() for _, line in block)
    text = results.MACRO.sub(_mask, text)
    text = re.sub(r"(`+)(?:(?!\1)[\s\S])+?\1", lambda m: _mask(m, CODE), text)  # code spans, across lines too
    text = CONFIDENCE.sub(_mask, text)
    found = []
    for m in sorted([*WITH_UNIT.finditer(text), *RATIO.finditer(text)], key=lambda m: m.start()):
        number = block[text.count("\n", 0, m.start())][0]
        figure = " ".join(m[0].split())
        if not {_norm(figure), _norm(re.sub(r"[x×]$", "", figure))} & allowed[number]:
            found.append((number, figure))
    return found


def figures(prose: str) -> list[str]:
    """The numbers with a unit in one line of prose."""
    return [f for _, f in block_figures([(1, prose)])]


def markdown_blocks(text: str) -> list[list[tuple[int, str]]]:
    """The paragraphs of a Markdown page as (line number, text) blocks; a fenced block gives only its
    comments, one block each."""
    blocks: list[list[tuple[int, str]]] = [[]]
    fence = None
    for number, line in enumerate(text.splitlines(), 1):
        opened = results.FENCE.match(line)
        if fence is None and opened:
            fence = opened[1]
            blocks.append([])
        elif fence is not None and line.strip().startswith(fence):
            fence = None
        elif fence is None and line.strip():
            blocks[-1].append((number, line))
        elif fence is None:
            blocks.append([])
        elif "#" in line:
            blocks += [[(number, line[line.index("#"):])], []]
    return [b for b in blocks if b]


def toml_blocks(text: str) -> list[list[tuple[int, str]]]:
    """A recipe's comments as (line number, text) blocks: consecutive whole-line comments together, a
    comment after a setting alone."""
    blocks: list[list[tuple[int, str]]] = [[]]
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.lstrip()
        if stripped.startswith("#"):
            blocks[-1].append((number, stripped))
            continue
        blocks.append([])
        if " #" in line and line.count('"') % 2 == 0 and '"' not in line.split(" #", 1)[1]:
            blocks += [[(number, line.split(" #", 1)[1])], []]  # after a setting (not a "#" in a string)
    return [b for b in blocks if b]


def scan(path: Path, root: Path = ROOT) -> list[Finding]:
    text = path.read_text(encoding="utf-8")
    if HISTORY in text:
        return []
    blocks = toml_blocks(text) if path.suffix == ".toml" else markdown_blocks(text)
    name = str(path.relative_to(root))
    return [Finding(name, n, f) for block in blocks for n, f in block_figures(block)]


def checked_files(root: Path = ROOT) -> list[Path]:
    return [*sorted((root / "docs").rglob("*.md")), root / "README.md",
            *sorted((root / "motorlab" / "recipes").glob("*.toml"))]


def test_no_hand_typed_number_in_the_docs_readme_or_recipes():
    files = checked_files()
    assert len(files) > 20 and all(f.is_file() for f in files)
    findings = [f for path in files for f in scan(path)]
    assert not findings, ("numbers with a unit typed by hand (generate them with a macro from "
                          "docs/hooks/results.py, remove them, or mark a definition <!-- def: ... -->):\n"
                          + "\n".join(map(str, findings)))


def test_a_planted_hand_typed_number_is_found(tmp_path):
    """A copy of the docs with "took 3.2 h" planted in a page: reported at its file and line."""
    shutil.copytree(ROOT / "docs", tmp_path / "docs", ignore=shutil.ignore_patterns("*.png", "assets"))
    page = tmp_path / "docs" / "tutorials" / "synergies.md"
    lines = page.read_text().splitlines()
    lines.insert(10, "The full study took 3.2 h on this machine.")
    page.write_text("\n".join(lines) + "\n")
    found = [f for p in sorted((tmp_path / "docs").rglob("*.md")) for f in scan(p, tmp_path)]
    assert [str(f) for f in found] == ["docs/tutorials/synergies.md:11: 3.2 h"]


def test_a_planted_number_in_a_recipe_comment_or_a_code_comment_is_found(tmp_path):
    recipe = tmp_path / "r.toml"
    recipe.write_text('# about 45 min on 2 cores\nname = "x#y"  # 30 s here\nsteps = 3  # `10 s` is a setting\n')
    assert [(f.line, f.figure) for f in scan(recipe, tmp_path)] == [(1, "45 min"), (2, "30 s")]
    page = tmp_path / "p.md"
    page.write_text("```bash\nmotorlab run sar-hand --timeout 30s   # ~7.5 h on 2 cores\n```\n")
    assert [(f.line, f.figure) for f in scan(page, tmp_path)] == [(2, "~7.5 h")]


@pytest.mark.parametrize("line", [
    'The study took {{ result("sar_study", "settings.sar_sac_fast.projected_study_hours", "h") }} here.',
    "Set `--delay 0.2 s` and `until 3 h`.",
    "an IQM with its 95% CI, a 95% stratified-bootstrap interval and the 95% Wilson interval",
    "with τ = 0.2 s and a 50 ms target <!-- def: 0.2 s, 50 ms -->",
    "25 x 80 x 5 members, 5 × 1.5M env steps, 3 × `--report-every`, 5 seeds, 2 hands, myoLegWalk-v0",
])
def test_generated_code_confidence_and_defined_numbers_are_not_findings(line):
    assert figures(line) == []


@pytest.mark.parametrize(("line", "found"), [
    ("at 774 env steps/s and ~1.9 h, 12.7× faster", ["774 env steps/s", "~1.9 h", "12.7×"]),
    ("58-72 min, ~1.9–3.6 h, 30% of seeds, 41/s, 1.4826 x the median", ["58-72 min", "~1.9–3.6 h", "30%", "41/s",
                                                                        "1.4826 x"]),
    ("a 50 ms target, and 31 ms measured <!-- def: 50 ms -->", ["31 ms"]),
])
def test_measured_numbers_are_findings(line, found):
    assert sorted(figures(line)) == sorted(found)


UNITS = st.sampled_from(["h", "hours", "min", "minutes", "s", "seconds", "ms", "days", "%", "/s", "env steps/s",
                         "x", "×"])
VALUES = st.one_of(st.integers(0, 10**7).map(lambda n: f"{n:,}"),
                   st.floats(0.01, 999, allow_nan=False).map(lambda v: f"{v:.3g}"))  # 0.0123, 4.56, 789
WORDS = st.lists(st.sampled_from(["the", "study", "ran", "at", "on", "seeds", "SAR-RL", "(measured)", "a", "run"]),
                 max_size=6).map(" ".join)


@settings(max_examples=200, deadline=None)
@given(before=WORDS, value=VALUES, unit=UNITS, after=WORDS)
def test_any_number_with_a_unit_in_prose_is_found_and_none_in_a_macro_or_code(before, value, unit, after):
    sep = "" if unit in ("%", "/s", "x", "×") else " "  # 12%, 41/s, 1.7x; 3 h, 774 env steps/s
    figure = f"{value}{sep}{unit}"
    assert figure in figures(f"{before} {figure} {after}".strip() + ".")
    assert figures(f"{before} `{figure}` {after}") == []
    assert figures(f'{before} {{{{ result("f", "a.b", "h") }}}} {after}') == []
    assert figures(f"{before} {figure} {after} <!-- def: {figure} -->") == []


# ---- the macros (docs/hooks/results.py): what a page shows is the file's value, or the build stops

RESULTS = ROOT / "benchmarks" / "results"


def _json(name: str) -> dict:
    return json.loads((RESULTS / f"{name}.json").read_text())


def test_a_macro_shows_the_files_value_and_a_statistic_over_seeds_is_computed_now():
    from motorlab.intervals import across_seeds

    study, robot = _json("sar_study"), _json("sar_robot")
    hours = study["settings"]["sar_sac_fast"]["projected_study_hours"]
    line = ('took {{ result("sar_study", "settings.sar_sac_fast.projected_study_hours", "h") }}; '
            '{{ seeds("sar_robot", "sar_rl.per_seed") }}; {{ date("sar_robot") }}')
    assert results.render(line) == "; ".join([
        f"took {hours:.3g} h", across_seeds(robot["sar_rl"]["per_seed"]).text(results.number), robot["date"][:10]])
    # a key that holds a dot is matched whole
    pendulum = _json("pendulum_steps_to_success")
    steps = pendulum["delayed_tau_0.2s_action_and_observation"]["motorlab_fast"]["median_steps"]
    assert results.render('{{ result("pendulum_steps_to_success", '
                          '"delayed_tau_0.2s_action_and_observation.motorlab_fast.median_steps", "count") }}') \
        == f"{steps:,.0f}"


def test_macros_in_code_are_left_as_written():
    page = ('`{{ result("no_such_file", "x") }}`\n'
            '```\n{{ result("no_such_file", "x") }}\n```\n'
            '{{ result("sar_robot", "wall_seconds", "s") }}')
    lines = results.render(page).split("\n")
    assert lines[:4] == page.split("\n")[:4] and "{{" not in lines[4]


@pytest.mark.parametrize(("macro", "says"), [
    ('{{ result("no_such_benchmark", "a.b") }}', "no result file benchmarks/results/no_such_benchmark.json"),
    ('{{ result("sar_robot", "sar_rl.no_such_key") }}', "sar_robot.json has no 'no_such_key'"),
    ('{{ result("sar_robot", "sar_rl.per_seed") }}', "not a number"),
    ('{{ result("sar_robot", "wall_seconds", "furlongs") }}', "unknown form 'furlongs'"),
    ('{{ seeds("sar_robot", "wall_seconds") }}', "no list of per-seed values"),
    ('{{ steps("sar_robot", "sar_rl.per_seed") }}', "no per-seed {steps, budget} records"),
    ('{{ no_such_macro("sar_robot") }}', "unknown macro 'no_such_macro'"),
    ('{{ result(sar_robot) }}', "not literals"),
])
def test_a_macro_that_cannot_be_rendered_stops_the_page_naming_it(macro, says):
    from mkdocs.exceptions import PluginError

    class Page:
        class file:  # noqa: N801  (MkDocs' page.file.src_uri)
            src_uri = "tutorials/x.md"

    with pytest.raises(PluginError, match=re.escape(says)) as error:
        results.on_page_markdown(f"Some prose.\n\nIt took {macro}.\n", Page, None, None)
    assert str(error.value).startswith("docs/tutorials/x.md: ")


def test_a_strict_build_fails_on_a_missing_key_and_renders_a_present_one(tmp_path):
    """A site of one page with the hook, built by MkDocs itself."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "mkdocs.yml").write_text(f"site_name: t\nstrict: true\nhooks:\n  - {ROOT / 'docs/hooks/results.py'}\n")
    page = tmp_path / "docs" / "index.md"

    def build():
        return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                              cwd=tmp_path, capture_output=True, text=True, timeout=120,
                              env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})

    page.write_text('Took {{ result("sar_robot", "wall_seconds", "s") }}.\n')
    done = build()
    assert done.returncode == 0, done.stderr
    wall = _json("sar_robot")["wall_seconds"]
    assert f"Took {results.number(wall)} s." in (tmp_path / "site" / "index.html").read_text()
    page.write_text('Took {{ result("sar_robot", "wall_secs", "s") }}.\n')
    done = build()
    assert done.returncode != 0 and "docs/index.md: sar_robot.json has no 'wall_secs'" in done.stdout + done.stderr
