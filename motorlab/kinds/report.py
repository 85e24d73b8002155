"""The `report` and `plot` commands: an HTML report of run and study folders, and a run's plots.
They write no run folder; matplotlib and the report's domain code are imported when they run."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from rich.console import Console

from motorlab.command import Command, NoFolder
from motorlab.settings import Settings


class ReportSettings(Settings):
    """Which folders `motorlab report` shows, and where it writes the page."""

    paths: list[Path] = Field(min_length=1, description="Run folders and/or study folders")
    out: Path | None = Field(None, description="HTML file to write (default: report.html in the first PATH)")


class ReportCommand(Command[ReportSettings]):
    """Write one self-contained HTML report: headline tables, every plot and video, side by side.

    The runs side by side, their settings, library versions and TensorBoard links; the page opens
    offline.
    """

    name = "report"
    settings = ReportSettings
    invocation = NoFolder
    arguments = ("paths",)
    examples = (
        "motorlab report runs/pendulum   # -> runs/pendulum/report.html",
        "motorlab report runs/sar-rl runs/rl-e2e --out compare.html   # side by side",
    )

    def execute(self, settings: ReportSettings, how: NoFolder, console: Console | None, progress: bool) -> Path:
        from motorlab.report.html import build_report

        return build_report(settings.paths, settings.out)

    def report(self, result: Path, settings: ReportSettings, console: Console) -> None:
        console.print(f"written: {result}")


REPORT = ReportCommand()


class PlotSettings(Settings):
    """Which run `motorlab plot` draws."""

    run_dir: Path = Field(description="A run folder from train or evaluate")


class PlotCommand(Command[PlotSettings]):
    """Plot a run: learning curve (training runs) and the observation trace of one evaluation episode."""

    name = "plot"
    settings = PlotSettings
    invocation = NoFolder
    arguments = ("run_dir",)
    examples = ("motorlab plot runs/ppo   # -> runs/ppo/plots/*.png",)

    def execute(self, settings: PlotSettings, how: NoFolder, console: Console | None, progress: bool) -> list[Path]:
        from motorlab.media.figures import plot_run

        return plot_run(settings.run_dir)

    def report(self, result: list[Path], settings: PlotSettings, console: Console) -> None:
        for path in result:
            console.print(f"written: {path}")


PLOT = PlotCommand()
