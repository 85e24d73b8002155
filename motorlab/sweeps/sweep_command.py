"""`motorlab sweep`: a command or a study over seeds and settings, as a command."""

from __future__ import annotations

from typing import Any, ClassVar

from pydantic import Field, field_validator
from rich.console import Console

from motorlab.command import Command, Resumable
from motorlab.sweeps.grid import read_grid
from motorlab.sweeps.targets import TargetSettings


class SweepSettings(TargetSettings):
    # the target (TargetSettings) and the grid are read once, here: from the command line's text, or as Python
    # gives them (a `StepTarget` / `RecipeTarget`, a dict grid); the sweep sees them typed
    owner: ClassVar[str] = "sweep"

    seeds: int = Field(5, ge=1, description="Seeds per setting: 0..N-1")
    grid: list[str] | dict[str, list[Any]] | None = Field(None, description=(
        "KEY=V1,V2 (every combination runs). Commands: KEY is a setting (lr, n_envs, delay, normalize=true,false) "
        "or, for train, an SB3 hyperparameter as set.KEY (set.gamma=0.98,0.99). Recipes: FIELD for every step that has it, or STEP.FIELD. Values "
        "holding commas: separate them with |, e.g. lr='linear:1e-3,0|3e-4'"))

    @field_validator("grid")
    @classmethod
    def _read_grid(cls, value: list[str] | dict[str, list[Any]] | None) -> dict[str, list[Any]]:
        return read_grid(value)


class SweepCommand(Command[SweepSettings]):
    """Run a command or a study for several seeds (and settings), then aggregate across seeds.

    Aggregates with rliable: interquartile mean (IQM) and 95% stratified-bootstrap confidence
    intervals of final return, success rate and steps-to-success; probability of improvement
    between settings; performance profiles. Writes summary.json, aggregate.json, table.txt,
    plots/ and report.html in the sweep folder, and one run folder per trial (<setting>/seed<k>/,
    <setting> a slug of the grid values and their hash: lr=3e-4-3ddbad7f).
    Run the same command again (same --out) to resume: finished trials are kept.
    """

    name = "sweep"
    invocation = Resumable
    arguments = ("target",)
    examples = (
        'motorlab sweep "train InvertedPendulum-v5 --preset fast --until-solved" --seeds 5',
        'motorlab sweep "train InvertedPendulum-v5 --timesteps 20000" --seeds 3 --grid lr=3e-4,1e-3 --grid n_envs=1,2',
        "motorlab sweep pendulum --seeds 3 --grid ppo.timesteps=50000,100000   # a whole study per seed",
        'motorlab sweep "train Reacher-v5 --algo sac" --seeds 8 --backend ray --address 10.0.0.5:6379')

    def execute(self, settings: SweepSettings, how: Resumable, console: Console | None, progress: bool) -> Any:
        from motorlab.sweeps.sweep import run_sweep

        return run_sweep(settings.target, settings.seeds, settings.grid, settings.backend, settings.address,
                         settings.max_parallel, how.out, console=console)

    def report(self, result: Any, settings: SweepSettings, console: Console) -> None:
        console.print(f"\n[bold]Results:[/bold] {result['sweep_dir']}  (report.html, table.txt, summary.json, "
                      "aggregate.json, plots/*.png, <setting>/seed<k>/)")


SWEEP = SweepCommand()
