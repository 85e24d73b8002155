"""`motorlab run`: a study from a recipe, as a command (settings, run, printout)."""

from __future__ import annotations

from typing import Any

from pydantic import Field
from rich.console import Console

from motorlab.command import Command, Resumable
from motorlab.launcher import ExecutionSettings
from motorlab.recipes import load_recipe
from motorlab.report.results import DEMO_LABEL


class RunSettings(ExecutionSettings):
    recipe: str = Field(description="A bundled recipe name (pendulum) or a path to a TOML recipe")
    parallel_steps: int | None = Field(None, ge=1, description=(
        "Train steps that need nothing from each other (e.g. SAR-RL's chain and RL-E2E) run at once, each its own "
        "process, at most this many (default: the recipe's parallel_steps, else 1)"))
    check: bool = Field(False, description=(
        "Only validate the recipe and list its steps; run nothing. Validating imports the recipe's `imports`, env "
        "modules and reward files (it says which first)"))
    set: list[str] | None = Field(None, description=(
        "KEY=VALUE: set a field of the recipe (VALUE as TOML reads it). KEY: FIELD (every step that has it), "
        "STEP.FIELD (one step), or one of the recipe's [inputs] (--set sar=sar.npz)"))


class RunCommand(Command[RunSettings]):
    """Run a study from a TOML recipe: its steps, a printed table, summary.json and plots.

    Recipe format: see `motorlab recipes` and motorlab/recipes/pendulum.toml. A recipe with
    `seeds = N` trains every train step for N seeds in parallel and reports IQMs with
    confidence intervals; `motorlab sweep RECIPE --seeds N` repeats the whole study instead.
    Re-running an interrupted study into the same --out keeps the steps that finished with the
    same settings (a train step continues from its checkpoint); a finished one needs --resume
    (keep its finished steps, redo the rest) or --overwrite (replace it).
    """

    name = "run"
    invocation = Resumable
    arguments = ("recipe",)
    examples = ("motorlab run pendulum --out runs/pendulum", "motorlab run my_study.toml",
                "motorlab run sar-legs-published --set sar=sar.npz   # a recipe's input")

    def execute(self, settings: RunSettings, how: Resumable, console: Console | None, progress: bool) -> Any:
        from motorlab.studies import Execution, run_study

        console = console or Console(stderr=True)
        announce = _announce(console) if settings.check else None
        study = load_recipe(settings.recipe, _key_values(settings.set or []), announce=announce)
        if settings.check:
            return study
        return run_study(study, how.out, console=console, execution=Execution(
            settings.backend, settings.address, settings.max_parallel, settings.parallel_steps))

    def report(self, result: Any, settings: RunSettings, console: Console) -> None:
        if settings.check:
            console.print(f"{result.source}: valid, {len(result.steps)} steps: "
                          + ", ".join(f"{st.name} ({st.kind.name}"
                                      + (f", {len(st.seeds)} seeds" if st.seeds and len(st.seeds) > 1 else "") + ")"
                                      for st in result.steps))
            if result.demo:
                console.print(f"{DEMO_LABEL}: {result.demo}", highlight=False, markup=False)
            return
        console.print(f"\n[bold]Results:[/bold] {result['study_dir']}  (report.html, table.txt, summary.json, "
                      "plots/*.png, one folder per step)")


def _announce(console: Console):
    def announce(code: list[str]) -> None:  # what validating a recipe runs, said before it runs (docs: Safety)
        if code:
            console.print("validating imports (runs) this code: " + ", ".join(code), highlight=False, soft_wrap=True)
    return announce


def _key_values(items: list[str]) -> dict[str, str]:
    """--set KEY=VALUE items as written (the recipe reads VALUE as TOML)."""
    from motorlab.errors import MotorlabError

    given = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise MotorlabError(f"--set {item!r}: write KEY=VALUE, e.g. --set ppo.timesteps=50000.")
        given[key.strip()] = value
    return given


RUN = RunCommand()
