"""HTML reports, opened in a real headless Chromium (Debian's, driven by Playwright):
no console errors, no network, every image decoded and captioned, every video playable,
the findings and each step's labelled numbers first, and the full tables showing exactly
the numbers in summary.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from motorlab.report.html import fmt
from tests.helpers import ENV_ID, assert_ok, assert_one_line_error, read_summary, run_cli, run_here

CHROMIUM = "/usr/bin/chromium"

TINY_STUDY = f"""
name = "tiny"
description = "report test: PID, PPO on two seeds, a video"

[defaults]
env = "{ENV_ID}"
episodes = 2

[[steps]]
name = "pid"
kind = "evaluate"
policy = "pid"

[[steps]]
name = "ppo"
kind = "train"
algo = "ppo"
timesteps = 256
seeds = [0, 1]
hyperparams = {{ n_steps = 128, batch_size = 64 }}
solve_episodes = 2

[[steps]]
name = "ppo-eval"
kind = "evaluate"
policy = "@ppo"

[[steps]]
name = "video"
kind = "video"
run = "@pid"
width = 160  # 1000-step episodes: ~10 s each to render and encode at 640x480, ~1 s at this size
height = 120
"""


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("report")
    recipe = root / "tiny.toml"
    recipe.write_text(TINY_STUDY)
    assert_ok(run_cli("run", recipe, "--out", root / "study"))
    return root / "study"


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
        yield b
        b.close()


class Opened:
    """A report loaded in Chromium, with what the page logged and fetched."""

    def __init__(self, browser, path: Path):
        self.page = browser.new_page()
        self.errors: list[str] = []
        self.requests: list[str] = []
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.goto(path.resolve().as_uri())
        self.page.wait_for_load_state("load")

    def cells(self, selector: str) -> dict[str, tuple[float, str]]:
        """data-key -> (data-value, shown text) of the numeric cells under `selector`."""
        rows = self.page.eval_on_selector_all(
            f"{selector} td[data-value]", "tds => tds.map(t => [t.dataset.key, t.dataset.value, t.textContent])")
        return {k: (float(v), text.strip()) for k, v, text in rows}


def _check_page(opened: Opened) -> None:
    page = opened.page
    assert opened.errors == []
    assert all(u.startswith(("file:", "data:")) for u in opened.requests), opened.requests  # nothing online
    images = page.eval_on_selector_all("img", "imgs => imgs.map(i => [i.complete, i.naturalWidth, i.src.slice(0, 15)])")
    assert images and all(done and width > 0 and src == "data:image/png;" for done, width, src in images)
    check_captions(page)
    videos = page.evaluate("""() => Promise.all(Array.from(document.querySelectorAll('video')).map(v =>
        v.readyState >= 1 ? Promise.resolve([v.duration, v.error, v.src.slice(0, 15)]) : new Promise(resolve => {
            v.addEventListener('loadedmetadata', () => resolve([v.duration, v.error, v.src.slice(0, 15)]));
            v.addEventListener('error', () => resolve([0, v.error && v.error.code, v.src.slice(0, 15)]));
        })))""")
    for duration, error, src in videos:
        assert error is None and duration > 0 and src == "data:video/mp4;"
    assert page.evaluate("document.createElement('video').canPlayType('video/mp4; codecs=\"avc1.42E01E\"')")


def check_captions(page) -> None:
    """Every figure and video says in one line what it shows (not just its file name)."""
    captions = page.eval_on_selector_all("figure", "fs => fs.map(f => [f.querySelector('img, video').title || '', "
                                                   "(f.querySelector('figcaption') || {}).textContent || ''])")
    for name, caption in captions:
        if "learning curve" in name or "·" in caption:
            continue  # the comparison's curves are captioned with their run and seed
        assert len(caption) > 25 and not caption.endswith((".png", ".mp4")) and "\n" not in caption.strip(), caption


def headline_numbers(page, selector: str = "table.steps") -> dict[str, list[tuple[str, str, str | None]]]:
    """Per step row: (label, text, data-value) of each headline number it shows."""
    rows = page.eval_on_selector_all(f"{selector} tbody tr", """rows => rows.map(r => [r.dataset.step,
        Array.from(r.querySelectorAll('.number')).map(n => [n.querySelector('.label').textContent,
            n.querySelector('.text').textContent, n.dataset.value === undefined ? null : n.dataset.value,
            n.dataset.key])])""")
    return {step: [tuple(n) for n in numbers] for step, numbers in rows}


def _numbers(summary: dict) -> dict[str, float]:
    return {k: v for k, v in summary.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def test_study_report_opens_cleanly_and_shows_the_summary_numbers(study, browser):
    report = study / "report.html"
    assert report.is_file()  # every study ends by writing it
    opened = Opened(browser, report)
    _check_page(opened)
    assert len(opened.page.query_selector_all("video")) == 2  # the video step took episodes = 2 from [defaults]

    summary = read_summary(study)
    shown = opened.cells("table.study")  # the full summary, one click away
    expected = {k: v for k, v in _numbers(summary).items() if "." in k}
    assert expected and set(expected) <= set(shown)
    for key, value in expected.items():
        assert shown[key] == (pytest.approx(value), fmt(value)), key

    numbers = headline_numbers(opened.page)
    assert list(numbers) == summary["steps"]
    for step, cells in numbers.items():
        assert cells and all(label and text.strip() and text != "–" for label, text, _, _ in cells), step
        for _, _, value, key in cells:  # each shown number is the summary's
            if value is not None and isinstance(summary.get(key), (int, float)):
                assert float(value) == pytest.approx(summary[key]), key
    labels = {label: text for label, text, _, _ in numbers["pid"]}
    # the pendulum has no success flag: a success is the maximum return, and the label says so
    assert labels["success (return ≥ 1000)"] == "100%" and labels["falls"] == "0/2"
    assert labels["return"] == "1,000.0 ± 0.0"
    assert not any(label.startswith("return IQM") for label, *_ in numbers["ppo"])  # 2 seeds: an IQM trims nothing
    assert {label for label, *_ in numbers["ppo"]} >= {"return", "success (return ≥ 1000)", "seeds",
                                                      "trained for (all seeds)"}

    runs = {"pid": study / "pid", "ppo/seed0": study / "ppo" / "seed0", "ppo/seed1": study / "ppo" / "seed1",
            "ppo-eval/seed0": study / "ppo-eval" / "seed0", "ppo-eval/seed1": study / "ppo-eval" / "seed1",
            "video": study / "video"}  # an evaluation of a two-seed step evaluates both seeds
    for label, run_dir in runs.items():
        cells = opened.cells(f'table.run[data-run="{label}"]')
        for key, value in _numbers(read_summary(run_dir)).items():
            assert cells[key] == (pytest.approx(value), fmt(value)), (label, key)


def test_study_report_opens_with_its_findings(study, browser):
    page = Opened(browser, study / "report.html").page
    findings = page.eval_on_selector_all("table.findings tbody tr", """rows => rows.map(r => [r.dataset.step,
        r.dataset.key, r.querySelector('th').textContent, r.querySelector('td.value').textContent,
        r.querySelectorAll('td')[1].textContent, r.querySelectorAll('td')[2].textContent])""")
    # the recipe names none: each step's own (success where the task defines it)
    assert [(step, key) for step, key, *_ in findings] == [("pid", "success_rate"), ("ppo", "success_rate"),
                                                           ("ppo-eval", "success_rate")]
    pid, ppo = findings[0], findings[1]
    # one run: no interval over seeds, but its episodes give one (Wilson's, never [100%, 100%])
    assert pid[2:5] == ["pid: success", "100%", "one run"]
    assert pid[5].startswith("episodes: 100% [") and "95% Wilson interval over" in pid[5], pid[5]
    assert "pooled from 1 seed(s)" in pid[5] and "100%, 100%]" not in pid[5]
    # two seeds: their mean, named so, with their range (named so: no CI from 2 seeds) unless they
    # agree; the pooled episodes' interval
    assert ppo[4].startswith("seed0 ") and ", seed1 " in ppo[4]
    across = ppo[5].partition("episodes: ")[0]
    assert across.startswith("mean ") and "95%" not in across, ppo[5]
    assert ("] (range of 2 seeds, not a confidence interval: one needs 5 seeds)" in across
            or "(the 2 seeds agree; no confidence interval below 5 seeds)" in across and "[" not in across), ppo[5]
    assert "episodes: " in ppo[5] and "pooled from 2 seed(s)" in ppo[5], ppo[5]
    first = page.evaluate("Array.from(document.querySelectorAll('h3, table.steps, figure')).map(e => e.tagName)")
    assert first[0] == "H3" and first.index("TABLE") > first.index("FIGURE")  # findings, figures, then the steps


def test_no_empty_figure(study):
    assert (study / "plots" / "returns.png").is_file()
    assert not (study / "plots" / "steps_to_success.png").exists()  # no step trains until solved: nothing to chart


def test_study_report_compares_seeds_side_by_side(study, browser):
    page = Opened(browser, study / "report.html").page
    seeds = page.eval_on_selector_all('table.comparison td[data-key="seed"]', "tds => tds.map(t => [t.dataset.run, t.dataset.value])")
    assert seeds == [["ppo/seed0", "0"], ["ppo/seed1", "1"]]
    returns = page.eval_on_selector_all('table.comparison td[data-key="return_mean"]', "tds => tds.map(t => +t.dataset.value)")
    assert returns == [pytest.approx(read_summary(study / "ppo" / f"seed{s}")["eval_return_mean"]) for s in (0, 1)]
    groups = page.eval_on_selector_all("table.comparison tr.group, table.comparison tbody th",
                                       "ths => ths.map(t => t.textContent)")
    assert groups.index("results") < groups.index("return") < groups.index("setup") < groups.index("trained for")
    assert "wall_seconds" not in groups  # raw keys stay in the full table
    captions = page.eval_on_selector_all("#comparison ~ .grid figcaption", "f => f.map(x => x.textContent)")
    assert "ppo/seed0 · seed 0" in captions and "ppo/seed1 · seed 1" in captions


def test_report_has_settings_versions_and_tensorboard_links(study, browser):
    page = Opened(browser, study / "report.html").page
    settings = page.eval_on_selector_all('section[id="run-ppo/seed1"] details pre', "p => p.map(x => x.textContent)")
    assert len(settings) == 1 and 'algo = "ppo"' in settings[0] and "seed = 1" in settings[0]
    env = json.loads((study / "ppo" / "seed1" / "environment.json").read_text())
    versions = page.eval_on_selector_all("table.environment tr", "rows => rows.map(r => r.textContent)")
    assert f"torch{env['packages']['torch']}" in versions
    links = page.eval_on_selector_all('section[id="run-ppo/seed0"] a[href$="tensorboard/"]',
                                      "a => a.map(x => x.getAttribute('href'))")
    assert links == ["ppo/seed0/tensorboard/"] and (study / links[0]).is_dir()


def test_report_of_two_run_folders(ppo_run, fast_run, tmp_path, browser):
    out = tmp_path / "compare.html"
    proc = run_cli("report", ppo_run, fast_run, "--out", out)
    assert_ok(proc)
    assert str(out) in proc.stdout
    opened = Opened(browser, out)
    _check_page(opened)
    runs = opened.page.eval_on_selector_all("table.comparison thead a", "a => a.map(x => x.textContent)")
    assert runs == [ppo_run.name, fast_run.name]
    for run_dir in (ppo_run, fast_run):
        cells = opened.cells(f'table.run[data-run="{run_dir.name}"]')
        for key, value in _numbers(read_summary(run_dir)).items():
            assert cells[key] == (pytest.approx(value), fmt(value))


def test_report_bad_paths(tmp_path, ppo_run):
    assert_one_line_error(run_here("report", tmp_path / "missing"), "does not exist")
    (tmp_path / "empty").mkdir()
    assert_one_line_error(run_here("report", tmp_path / "empty"), "not a finished run or study folder")
    (tmp_path / "folder.html").mkdir()
    assert_one_line_error(run_here("report", ppo_run, "--out", tmp_path / "folder.html"), "is a folder")
