"""The CLI reference page, generated from the commands' own `--help` at every docs build.

MkDocs runs this file as a hook (mkdocs.yml: `hooks:`): in docs/reference/cli.md the line
`<!-- cli-reference -->` becomes one section per command, each holding the text `motorlab ... --help`
prints under HELP_ENV, so the page cannot drift from the CLI. The text is made in a child process
(`python docs/hooks/cli_reference.py`), so that the width and colour settings below hold from the start.

tests/test_docs.py checks the built page against `motorlab ... --help` run for every command.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

PLACEHOLDER = "<!-- cli-reference -->"
PAGE = "reference/cli.md"
# Plain text, no colour, a fixed width.
HELP_ENV = {"NO_COLOR": "1", "TERM": "dumb", "COLUMNS": "80", "MOTORLAB_HELP_PAGE": "1"}


def commands() -> list[tuple[str, ...]]:
    """Every command path of the CLI, from the Click app itself: () for `motorlab`, then each command
    in the order `motorlab --help` lists them, a group followed by its subcommands."""
    from motorlab.cli import app

    found: list[tuple[str, ...]] = []

    def walk(cmd, path: tuple[str, ...], ctx) -> None:
        found.append(path)
        if hasattr(cmd, "list_commands"):
            sub_ctx = cmd.context_class(cmd, info_name=path[-1] if path else "motorlab", parent=ctx)
            for name in cmd.list_commands(sub_ctx):
                sub = cmd.get_command(sub_ctx, name)
                if sub is not None and not sub.hidden:
                    walk(sub, (*path, name), sub_ctx)

    walk(app, (), None)
    return found


def help_text(path: tuple[str, ...]) -> str:
    """What `motorlab *path --help` prints (trailing blank space removed); call it in a process that
    runs under HELP_ENV."""
    from motorlab.cli import app

    cmd = app
    ctx = cmd.context_class(cmd, info_name="motorlab", **cmd.context_settings)  # as `motorlab --help` makes it
    for name in path:
        cmd = cmd.get_command(ctx, name)
        ctx = cmd.context_class(cmd, info_name=name, parent=ctx, **cmd.context_settings)
    return normalize(ctx.get_help())


def normalize(text: str) -> str:
    """Help text as the page holds it: no trailing spaces on a line, no blank lines at the end."""
    return "\n".join(line.rstrip() for line in text.splitlines()).strip("\n")


def anchor(path: tuple[str, ...]) -> str:
    """The id of a command's section on the page: motorlab-synergies-fit."""
    return "-".join(("motorlab", *path))


def render() -> str:
    """The page's generated part: one section per command with its help in a code block."""
    parts = []
    for path in commands():
        title = " ".join(("motorlab", *path))
        level = "##" if len(path) <= 1 else "###"
        parts.append(f"{level} `{title}` {{#{anchor(path)}}}\n\n```text\n{help_text(path)}\n```\n")
    return "\n".join(parts)


def generate() -> str:
    """render() in a child process under HELP_ENV (the terminal's width is read when Click formats)."""
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, __file__], cwd=root, env={**os.environ, **HELP_ENV},
                          capture_output=True, text=True, timeout=120)
    if proc.returncode != 0:
        raise RuntimeError(f"docs/hooks/cli_reference.py failed:\n{proc.stderr}")
    return proc.stdout


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs hook
    if page.file.src_uri != PAGE:
        return markdown
    if PLACEHOLDER not in markdown:
        raise RuntimeError(f"docs/{PAGE} lost its {PLACEHOLDER} line")
    return markdown.replace(PLACEHOLDER, generate())


if __name__ == "__main__":
    if os.environ.get("MOTORLAB_HELP_PAGE") != "1":  # run as a script by hand: under HELP_ENV, once
        os.environ.update(HELP_ENV)
        os.execv(sys.executable, [sys.executable, __file__])
    sys.stdout.write(render())
