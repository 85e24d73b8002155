"""The reports of the bundled quick recipes (what `make demo` shows a new user), at the tests' scale,
opened in headless Chromium: the recipe's findings come first and are all filled, every step
shows its labelled numbers, every figure has data and a caption, and the screenshot script
that makes the README's pictures works on them."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from motorlab.recipes import load_recipe
from tests.helpers import assert_ok, read_summary, run_cli, scaled_recipe
from tests.report.test_html import Opened, _check_page, browser, headline_numbers  # noqa: F401  (browser: a fixture)

REPO = Path(__file__).resolve().parents[2]


# Both at the tests' scale (helpers.SCALED: what is tested does not depend on the budgets).
# sar-hand-quick is the study conftest.py runs once for this file and test_sar_study.py.
@pytest.fixture(scope="module", params=["reacher-quick", "sar-hand-quick"])
def bundled(request, tmp_path_factory) -> tuple[str, Path]:
    if request.param == "sar-hand-quick":
        return request.param, request.getfixturevalue("sar_hand_quick")[1]
    folder = tmp_path_factory.mktemp(request.param)
    assert_ok(run_cli("run", scaled_recipe(request.param, folder), "--out", folder / "study", timeout=900))
    return request.param, folder / "study"


def test_report_opens_with_the_recipes_findings_all_filled(bundled, browser):  # noqa: F811
    name, out = bundled
    opened = Opened(browser, out / "report.html")
    _check_page(opened)  # no errors, nothing online, every image decoded and captioned
    rows = opened.page.eval_on_selector_all("table.findings tbody tr", """rows => rows.map(r => [r.dataset.step,
        r.dataset.key, r.querySelector('th').textContent, r.querySelector('td.value').textContent,
        r.querySelectorAll('td')[1].textContent, r.querySelectorAll('td')[2].textContent])""")
    specs = load_recipe(name).findings
    assert specs and [(step, key, label) for step, key, label, *_ in rows] == [(f.step, f.key, f.label)
                                                                                 for f in specs]
    summary = read_summary(out)
    several = 0
    for step, key, label, value, per_seed, over_seeds in rows:
        assert value.strip() and value != "–" and f"{step}.{key}" in summary, label
        seeds = 0 if per_seed == "one run" else len(per_seed.split(", "))
        several += seeds > 1
        across, _, pooled = over_seeds.partition("episodes: ")
        if key == "steps_to_success":  # k of n and the median, each interval named in the text
            assert seeds < 2 or "95% Wilson interval" in across, label
        elif seeds >= 5:  # a 95% CI and what it is, or that the seeds agree
            assert ("[" in across and f"95% stratified-bootstrap CI over {seeds} seeds" in across
                    or "seeds agree" in across), label
        elif seeds >= 2:  # no CI from 2-4 seeds (a bootstrap of them is about their range): the range, named so
            assert "95%" not in across, label
            assert (f"] (range of {seeds} seeds, not a confidence interval" in across
                    or f"the {seeds} seeds agree" in across and "[" not in across), label
            assert across.startswith("mean " if seeds < 4 else "IQM "), label  # the IQM of 2-3 trims nothing
            if key == "success_rate":  # the episodes of every seed, pooled: Wilson's interval
                assert "95% Wilson interval over" in pooled and f"pooled from {seeds} seed(s)" in pooled, label
        assert_no_zero_width_interval(over_seeds, label)
    assert several or name == "reacher-quick"  # sar-hand-quick's findings are over its 2 seeds


def assert_no_zero_width_interval(text: str, label: str) -> None:
    """No "[x, x]" shown as an interval (the bootstrap of one seed, or the range of equal seeds)."""
    import re

    for low, high in re.findall(r"\[([^,\]]+), ([^\]]+)\]", text):
        assert low.strip() != high.strip(), (label, text)


def test_every_step_shows_its_numbers(bundled, browser):  # noqa: F811
    _, out = bundled
    numbers = headline_numbers(Opened(browser, out / "report.html").page)
    assert list(numbers) == read_summary(out)["steps"]
    for step, cells in numbers.items():
        assert cells, f"{step}: no headline numbers"
        assert all(label.strip() and text.strip() and text != "–" for label, text, *_ in cells), (step, cells)


def test_no_figure_is_empty(bundled):
    """Each PNG of the study has a caption (written only when the figure had data)."""
    from motorlab.report.plots import figure_caption

    _, out = bundled
    pngs = sorted(out.rglob("*.png"))
    assert pngs
    for png in pngs:
        assert figure_caption(png), png
    if not any(getattr(s.settings, "until_solved", False) for s in load_recipe(bundled[0]).steps):
        assert not (out / "plots" / "steps_to_success.png").exists()  # no step aims to solve: no chart


def test_screenshot_script(bundled, tmp_path):
    name, out = bundled
    png = tmp_path / f"{name}.png"
    proc = subprocess.run([sys.executable, REPO / "scripts" / "screenshots.py", f"{out / 'report.html'}={png}",
                           "--height", "600"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    from PIL import Image

    with Image.open(png) as image:
        assert image.size == (1280, 600)
        assert len(set(image.convert("L").getdata())) > 50  # text and figures, not a blank page
