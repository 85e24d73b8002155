"""The `motorlab` command: one sub-command per `Command` in motorlab.registry, each made from its
settings model by motorlab.commandline. Nothing here knows a command's options.

User mistakes (motorlab.errors.MotorlabError, invalid settings, Click's usage errors) and what the
system refuses (a full disk, a name too long, a symlink loop: motorlab.errors.StorageError) print
one line and exit with status 2. A stopped step leaves its run folder without summary.json, i.e.
visibly unfinished (a training's checkpoint kept for --resume): SIGINT (Ctrl-C), SIGTERM and SIGHUP
stop a command alike (motorlab.processes), and it exits with 128 + the signal's number, as a shell
shows a process that signal ended: 130 for Ctrl-C, 143 for SIGTERM (`timeout`, `kill`, Slurm), 129
for SIGHUP.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager, suppress

os.environ.setdefault("MUJOCO_GL", "egl")  # offscreen rendering works without a display

import click  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.markup import escape  # noqa: E402

from motorlab.command import Command  # noqa: E402
from motorlab.commandline import Given, click_command  # noqa: E402
from motorlab.errors import MotorlabError, StorageError  # noqa: E402
from motorlab.processes import stopped_by_signals  # noqa: E402
from motorlab.registry import COMMANDS, GROUPS  # noqa: E402
from motorlab.user_modules import import_modules  # noqa: E402

HELP = (
    "Learn motor control of simulated bodies in MuJoCo.\n\n"
    "Each command is one step; it writes a run folder (--out, default runs/<step>-<time>) with "
    "config.toml, summary.json, metrics.csv, tensorboard/ and plots/.\n\n"
    "\b\nStart here:  motorlab run pendulum   (the robust-pendulum study, a few minutes)\n\n"
    "Your own env: any command takes Gymnasium's MODULE:ID form (motorlab train mypkg.envs:MyArm-v0), "
    "or --import MODULE (repeatable, anywhere on the line) for a module that registers several ids; "
    "run folders record the modules, so later commands on them import them again.")
CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 120}

err = Console(stderr=True)
# Wide enough for study tables when output goes to a file or CI log.
stdout = Console(width=None if sys.stdout.isatty() else 150)


def run_command(cmd: Command, given: Given) -> None:
    """What every command does: the invocation, the settings under what it brings (--config), run, print."""
    how = cmd.how(**given.how)
    settings = cmd.make(how, **given.fields)
    result = cmd.invoke(settings, how, console=stdout)
    cmd.report(result, settings, stdout)


def build() -> click.Group:
    """The command tree: top-level commands, and the groups (synergies, dynamics) of the others."""
    app = click.Group("motorlab", help=HELP, context_settings=CONTEXT, no_args_is_help=True)
    groups = {"": app}
    for name, text in GROUPS.items():
        groups[name] = click.Group(name, help=text, short_help=text.split(":")[0], context_settings=CONTEXT,
                                   no_args_is_help=True)
        app.add_command(groups[name])
    for cmd in COMMANDS.values():
        *group, _ = cmd.command.split()
        groups[" ".join(group)].add_command(click_command(cmd, run_command))
    return app


app = build()


def main() -> None:
    """Entry point: run the app, turning user mistakes into one-line errors.

    Click's own mistakes (unknown option, a value of the wrong type, a missing argument) are
    caught here too, instead of in Click's standalone mode, which prints them under the usage
    text: every mistake reads the same, `error: ...` on one line, exit status 2."""
    with one_line_errors():
        import_modules(_take_imports(sys.argv), "given with --import")
        try:
            code = app.main(args=sys.argv[1:], prog_name="motorlab", standalone_mode=False)
        except click.exceptions.NoArgsIsHelpError as e:
            click.echo(e.ctx.get_help())
            sys.exit(2)  # a group given no command: its help was printed
        except click.UsageError as e:
            where = e.ctx.command_path if e.ctx is not None else "motorlab"
            raise MotorlabError(f"{e.format_message()} (see `{where} --help`)") from None
        except click.ClickException as e:
            raise MotorlabError(e.format_message()) from None
        except click.exceptions.Abort:
            raise KeyboardInterrupt from None
    sys.exit(code if isinstance(code, int) else 0)


@contextmanager
def one_line_errors(take: tuple[int, ...] = (), grace: float = 60.0) -> Iterator[None]:
    """A user's mistake, or an error of the system about a path (disk full, permission, name too long),
    as one line and status 2; SIGINT, SIGTERM and SIGHUP as a stop with status 128 + the signal, its
    cleanup given `grace` seconds (the launcher gives its trials 20). Also for motorlab.worker, which
    gives `take`: the signals its parent stops it with, even if ignored."""
    with stopped_by_signals(take, grace) as stop:
        try:
            yield
        except MotorlabError as e:
            _error(str(e))
        except (OSError, RuntimeError) as e:  # a file or folder the system refused, wherever: one table of causes
            if (known := StorageError.of(e)) is None:
                raise
            _error(str(known))
        except KeyboardInterrupt:
            what = "interrupted" if stop.signum == signal.SIGINT else f"interrupted by {stop.name}"
            with suppress(OSError):  # after SIGHUP the terminal may be gone
                err.print(f"[yellow]{what}[/yellow]: the run folder has no summary.json, so it stays marked "
                          "unfinished.", highlight=False, soft_wrap=True)
            sys.exit(stop.status)


def _take_imports(argv: list[str]) -> list[str]:
    """Remove every `--import MODULE` (or `--import=MODULE`) from argv, wherever it stands, and return the
    modules: `--import` works the same before or after any command (see the app's help)."""
    modules, rest, i = [], [argv[0]], 1
    while i < len(argv):
        a = argv[i]
        if a == "--":
            rest += argv[i:]
            break
        if a == "--import":
            if i + 1 == len(argv):
                raise MotorlabError("--import needs a module name, e.g. --import mypkg.envs.")
            modules.append(argv[i + 1])
            i += 2
            continue
        if a.startswith("--import="):
            modules.append(a.split("=", 1)[1])
        else:
            rest.append(a)
        i += 1
    argv[:] = rest
    return modules


def _error(message: str, code: int = 2) -> None:
    err.print(f"[red]error:[/red] {escape(message)}", highlight=False, soft_wrap=True)
    sys.exit(code)


if __name__ == "__main__":
    main()
