"""The `synergies import-sklearn` and `synergies export-sklearn` commands: a SAR between motorlab's
sar.npz and MyoSuite's scikit-learn pickles. They write a file or folder they are given, no run
folder; scikit-learn and MyoSuite are imported when they run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import Field
from rich.console import Console

from motorlab.command import Command, NoFolder
from motorlab.settings import Settings


class ImportSklearnSettings(Settings):
    """Which published SAR `synergies import-sklearn` converts, and where to."""

    folder: Path = Field(description="A MyoSuite 2.x tutorial SAR (pca.pkl, ica.pkl, normalizer.pkl) or a MyoSuite "
                         "3.0 SynergyModel folder (pca.pkl, ica.pkl, scaler.pkl, metadata.npz); the layout is detected")
    out: Path = Field(description="The sar.npz to write")
    trust: bool = Field(False, description="Allow unpickling these files (they can run code)")


class ImportSklearnCommand(Command[ImportSklearnSettings]):
    """Convert a published scikit-learn SAR (joblib pickles) to sar.npz, checked against sklearn's own inverse chain.

    Whitening, the scaler's range and MyoSuite 3.0's scaler margin are kept exactly: the sar.npz decodes
    every synergy vector as pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z))) does.
    Nothing is unpickled without --trust.
    """

    name = "import-sklearn"
    command = "synergies import-sklearn"
    settings = ImportSklearnSettings
    invocation = NoFolder
    arguments = ("folder",)
    examples = (
        "motorlab synergies import-sklearn published/manipulation --trust --out sar-hand.npz",
        "motorlab synergies import-sklearn my_synergy_model --trust --out sar.npz   # MyoSuite 3.0",
    )

    def execute(self, settings: ImportSklearnSettings, how: NoFolder, console: Console | None, progress: bool) -> Any:
        from motorlab.synergies.sklearn_import import import_sklearn

        return import_sklearn(settings.folder, trust=settings.trust, out=settings.out)

    def report(self, sar: Any, settings: ImportSklearnSettings, console: Console) -> None:
        err_max = sar.metadata.get("import_check_max_abs_error")
        console.print(f"{sar.n_synergies} synergies x {sar.n_muscles} muscles -> {settings.out}"
                      + (f" (decode matches scikit-learn, max abs error {err_max:.1e})" if err_max is not None else ""))


IMPORT_SKLEARN = ImportSklearnCommand()


class ExportSklearnSettings(Settings):
    """Which SAR `synergies export-sklearn` writes, and where."""

    sar: Path = Field(description="The sar.npz to export (from `synergies fit` or `import-sklearn`)")
    out: Path = Field(description="New folder for pca.pkl, ica.pkl, scaler.pkl, metadata.npz (it must not exist, "
                      "or be empty)")


class ExportSklearnCommand(Command[ExportSklearnSettings]):
    """Write a SAR as a MyoSuite 3.0 SynergyModel folder, for MyoSuite's load_synergy_model.

    The folder holds fitted scikit-learn PCA, FastICA and MinMaxScaler (joblib) whose inverse chain equals
    motorlab's decode; it is checked on random synergy vectors before the folder appears. The scaler keeps the
    SAR's synergy range (-1 to 1 for `synergies fit`, 0 to 1 in MyoSuite's own fits).

    pca-ica, pca and imported SARs export; nmf SARs cannot (NMF is not a PCA -> ICA chain).
    Needs MyoSuite: pip install 'motorlab[myosuite]'.
    """

    name = "export-sklearn"
    command = "synergies export-sklearn"
    settings = ExportSklearnSettings
    invocation = NoFolder
    arguments = ("sar",)
    examples = (
        "motorlab synergies export-sklearn runs/fit/sar.npz --out sar-myosuite   "
        "# then in MyoSuite (sar_extraction): load_synergy_model('sar-myosuite')",
    )

    def execute(self, settings: ExportSklearnSettings, how: NoFolder, console: Console | None, progress: bool) -> Any:
        from motorlab.synergies.sklearn_export import export_sklearn

        return export_sklearn(settings.sar, settings.out)

    def report(self, result: Any, settings: ExportSklearnSettings, console: Console) -> None:
        console.print(f"{result.n_synergies} synergies x {result.n_muscles} muscles -> {settings.out} (MyoSuite's "
                      f"chain matches motorlab's decode, max abs error {result.max_abs_error:.1e})")


EXPORT_SKLEARN = ExportSklearnCommand()


class PlotSettings(Settings):
    """Which synergy set `synergies plot` draws, from what, and where."""

    sar: Path = Field(description="A sar.npz, or a `synergies fit` run folder")
    out: Path = Field(description="Folder for heatmap.png, coefficients.png and vaf.png (created if missing)")
    activations: Path | None = Field(None, description="activations.npz (or its folder) for the coefficients over "
                                     "the first episodes (default: those a fit run folder was fitted to)")
    vaf: Path | None = Field(None, description="A `synergies vaf` run folder: its curve, band over folds and chosen N")
    episodes: int = Field(3, gt=0, description="Episodes whose coefficients are drawn")
    names_from: str | None = Field(None, description="An env id whose MuJoCo actuator names label a SAR saved "
                                   "without muscle names")


class PlotCommand(Command[PlotSettings]):
    """Draw a synergy set: the named muscle-weight heatmap, coefficients over episodes, the VAF curve with its band.

    The heatmap's rows are the muscles in the model's order, named as the model names its actuators (or by
    --names-from for a SAR saved without names); each synergy is scaled to unit length. The coefficients are the
    SAR's encoding of the activations, over the first --episodes episodes. The VAF curve comes from a `synergies
    vaf` run (--vaf): the folds' mean with +-1 SD and the N each criterion chose. `synergies fit` draws the same
    figures into its own run folder.
    """

    name = "plot-synergies"
    command = "synergies plot"
    settings = PlotSettings
    invocation = NoFolder
    arguments = ("sar",)
    examples = ("motorlab synergies plot runs/fit --vaf runs/vaf --out figures",
                "motorlab synergies plot sar-hand.npz --names-from myoHandReorient8-v0 --activations runs/collect "
                "--out figures")

    def execute(self, settings: PlotSettings, how: NoFolder, console: Console | None, progress: bool) -> Any:
        from motorlab.synergy_runs.plotting import plot_synergies

        return plot_synergies(settings.sar, settings.out, settings.activations, settings.vaf, settings.episodes,
                              settings.names_from)

    def report(self, written: Any, settings: PlotSettings, console: Console) -> None:
        console.print("written: " + ", ".join(str(p) for p in written))


PLOT_SYNERGIES = PlotCommand()
