"""The documentation site (mkdocs.yml, docs/): it builds strictly (a warning fails the build), every
page opens in a real headless Chromium (Debian's, driven by Playwright, as the report tests do) from
file://, as a reader opens site/index.html, with no console error, no request leaving the machine,
no broken internal link or anchor and no missing image; and the CLI reference holds exactly what
`motorlab ... --help` prints, for every command the Typer app has."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from tests.helpers import docs_hook

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = "/usr/bin/chromium"




cli_reference = docs_hook("cli_reference")


@pytest.fixture(scope="module")
def build(tmp_path_factory) -> tuple[subprocess.CompletedProcess, Path]:
    """`mkdocs build --strict` into a folder of its own (not site/, which `make docs` owns)."""
    site = tmp_path_factory.mktemp("docs") / "site"
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    return proc, site


@pytest.fixture(scope="module")
def site(build) -> Path:
    proc, site = build
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    return site


def test_the_site_builds_strictly_without_a_warning(build):
    proc, site = build
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output
    assert "WARNING" not in output and "ERROR" not in output, output
    for page in ("index.html", "getting-started.html", "reference/cli.html", "reference/python.html",
                 "design.html", "changelog.html", "tutorials/robust-policies.html"):
        assert (site / page).is_file(), page


class _Ids(HTMLParser):
    """The element ids of a page (the anchors a link's #fragment may name)."""

    def __init__(self):
        super().__init__()
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        self.ids.update(v for k, v in attrs if k in ("id", "name") and v)


def _ids(path: Path, cache: dict[Path, set[str]]) -> set[str]:
    if path not in cache:
        parser = _Ids()
        parser.feed(path.read_text(encoding="utf-8"))
        cache[path] = parser.ids
    return cache[path]


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--headless", "--no-sandbox", "--disable-gpu"])
        yield b
        b.close()


def test_every_page_opens_cleanly_with_no_broken_link_or_image(site, browser):
    pages = sorted(p for p in site.rglob("*.html") if p.name != "404.html")  # 404.html: for a web server only
    assert len(pages) == len(list((ROOT / "docs").rglob("*.md"))) >= 19  # one per page of docs/
    ids: dict[Path, set[str]] = {}
    problems: list[str] = []
    images_seen = 0
    context = browser.new_context()
    for path in pages:
        name = path.relative_to(site).as_posix()
        page = context.new_page()
        errors: list[str] = []
        requests: list[str] = []
        page.on("console", lambda m, errors=errors: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e, errors=errors: errors.append(str(e)))
        page.on("requestfailed", lambda r, errors=errors: errors.append(f"failed: {r.url}"))
        page.on("request", lambda r, requests=requests: requests.append(r.url))
        page.goto(path.as_uri())
        page.wait_for_load_state("load")
        problems += [f"{name}: console: {e}" for e in errors]
        problems += [f"{name}: request off the machine: {u}" for u in requests
                     if not u.startswith(("file:", "data:", "blob:"))]

        images = page.eval_on_selector_all("img", "imgs => imgs.map(i => [i.getAttribute('src'), i.complete, "
                                                  "i.naturalWidth])")
        for src, complete, width in images:
            images_seen += 1
            if not (complete and width > 0):
                problems.append(f"{name}: image does not load: {src}")

        for href in page.eval_on_selector_all("a[href]", "as => as.map(a => a.href)"):
            url = urlsplit(href)
            if url.scheme != "file":
                continue  # external links (GitHub, papers) are not followed: the site works offline
            target = Path(unquote(url.path))
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                problems.append(f"{name}: broken link {href}")
            elif url.fragment and target.suffix == ".html" and unquote(url.fragment) not in _ids(target, ids):
                problems.append(f"{name}: no anchor #{url.fragment} in {target.relative_to(site)}")
        page.close()
    context.close()
    assert not problems, "\n".join(problems)
    assert images_seen >= 3  # the home page's three report screenshots at least


def test_search_works_offline(site, browser):
    """The search box finds a page from file://, with no server (Material's offline plugin)."""
    page = browser.new_page()
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.goto((site / "index.html").as_uri())
    page.click(".md-search__input")
    page.keyboard.type("robustness")  # key by key, as a reader types (Material searches on key events)
    page.wait_for_selector(".md-search-result__item", timeout=15_000)
    assert page.eval_on_selector_all(".md-search-result__item", "items => items.length") > 0
    assert errors == []
    page.close()


class _Sections(HTMLParser):
    """Per heading id on the CLI page: the text of the first code block after it."""

    def __init__(self):
        super().__init__()
        self.sections: dict[str, str] = {}
        self._heading: str | None = None
        self._in_pre = False
        self._text: list[str] = []

    def handle_starttag(self, tag, attrs):
        if re.fullmatch(r"h[1-6]", tag):
            self._heading = dict(attrs).get("id")
        elif tag == "pre" and self._heading and self._heading not in self.sections:
            self._in_pre, self._text = True, []

    def handle_endtag(self, tag):
        if tag == "pre" and self._in_pre:
            self._in_pre = False
            self.sections[self._heading] = "".join(self._text)

    def handle_data(self, data):
        if self._in_pre:
            self._text.append(data)


# `motorlab *path --help` for every path, through the console script's own entry point (motorlab.cli:main,
# argv and all) in one child process under the reference's environment: one CLI start instead of one per command.
HELP_RUNNER = """
import contextlib, io, json, sys
from motorlab.cli import main
helps = []
for path in json.loads(sys.argv[1]):
    sys.argv = ["motorlab", *path, "--help"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            main()
        except SystemExit as e:
            code = e.code
    helps.append([code, out.getvalue()])
json.dump(helps, sys.__stdout__)
"""


def _motorlab_helps(paths: list[tuple[str, ...]]) -> list[str]:
    proc = subprocess.run([sys.executable, "-c", HELP_RUNNER, json.dumps(paths)], capture_output=True, text=True,
                          timeout=120, cwd=ROOT, env={**os.environ, **cli_reference.HELP_ENV})
    assert proc.returncode == 0, proc.stderr
    helps = json.loads(proc.stdout)
    assert [code for code, _ in helps] == [0] * len(paths), helps
    return [cli_reference.normalize(text) for _, text in helps]


def test_the_cli_reference_is_each_commands_help(site):
    commands = cli_reference.commands()  # from the Typer app: a new command is covered by itself
    assert ("train",) in commands and ("synergies", "fit") in commands and ("dynamics", "check") in commands
    assert len(commands) == len(set(commands)) >= 20

    parser = _Sections()
    parser.feed((site / "reference/cli.html").read_text(encoding="utf-8"))
    helps = dict(zip(commands, _motorlab_helps(commands), strict=True))
    for path, text in helps.items():
        anchor = cli_reference.anchor(path)
        assert anchor in parser.sections, f"docs/reference/cli.md has no section for motorlab {' '.join(path)}"
        assert cli_reference.normalize(parser.sections[anchor]) == text, f"motorlab {' '.join(path)} --help"
    assert set(parser.sections) >= {cli_reference.anchor(p) for p in commands}

    # and the installed console script prints the same (one command, a real `motorlab ... --help`)
    exe = Path(sys.executable).with_name("motorlab")
    argv = [str(exe)] if exe.exists() else [sys.executable, "-m", "motorlab"]
    proc = subprocess.run([*argv, "synergies", "fit", "--help"], capture_output=True, text=True, timeout=120,
                          cwd=ROOT, env={**os.environ, **cli_reference.HELP_ENV})
    assert proc.returncode == 0 and cli_reference.normalize(proc.stdout) == helps[("synergies", "fit")]


def _documented(obj, seen: set[str]):
    """obj and what its section on the Python API page shows: a module's functions and classes, a class's
    public members."""
    if obj.is_alias:
        obj = obj.final_target
    if obj.path in seen:
        return
    seen.add(obj.path)
    yield obj
    if obj.is_module or obj.is_class:
        for member in obj.members.values():
            if member.is_alias or member.name.startswith("_") and member.name != "__getitem__":
                continue
            if obj.is_class or member.is_function or member.is_class:
                yield from _documented(member, seen)


@pytest.mark.fast
def test_api_docstrings_hold_no_bare_html():
    """Markdown takes `<time>` or `<a fit result>` in a docstring for an HTML tag: the word vanishes from
    the Python API page (or becomes a link). Such text belongs in backticks."""
    import griffe

    package = griffe.load("motorlab", search_paths=[str(ROOT)], resolve_aliases=False)
    page = (ROOT / "docs/reference/python.md").read_text(encoding="utf-8")
    seen: set[str] = set()
    bare = []
    for identifier in re.findall(r"^::: (\S+)", page, flags=re.M):
        for obj in _documented(package[identifier.removeprefix("motorlab.")], seen):
            fenced = False
            for line in (obj.docstring.value if obj.docstring else "").splitlines():
                if line.strip().startswith("```"):
                    fenced = not fenced
                elif not fenced and re.search(r"<[A-Za-z/!?]", re.sub(r"`[^`]*`", "", line)):
                    bare.append(f"{obj.path}: {line.strip()}")
    assert len(seen) > 20 and not bare, "\n".join(bare)
