"""The `import-emg` step kind: raw EMG from a CSV file to an activations.npz of normalized envelopes
(motorlab.synergies.emg), which `synergies vaf` and `fit`, and a recipe's later steps, read as they read
collected muscle activations."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from pydantic import Field, field_validator
from rich.console import Console

from motorlab.report.results import Metric
from motorlab.runs import atomic_write_npz
from motorlab.settings import Settings, Summary
from motorlab.stepkind import Artifact, StepKind
from motorlab.synergies.emg import BAND, DOWNSAMPLE, LOWPASS, ORDER, TRIAL_COLUMN
from motorlab.synergy_runs.activations import ACTIVATIONS

EMG = "emg"  # the signal an imported file holds, as activations.npz and sar.npz record it


class ImportEmgSettings(Settings):
    file: str = Field(description=f"A CSV of raw EMG: a header naming each muscle's column, then one row per sample; "
                      f"an optional column named `{TRIAL_COLUMN}` gives each row's trial (whole numbers, each trial's "
                      "rows together; filtered apart), else the recording is one trial; a `time` column is ignored")
    rate: float = Field(gt=0, description="The recording's sampling rate, Hz")
    band: list[float] = Field(default_factory=lambda: list(BAND), min_length=2, max_length=2,
                              description=f"Band-pass corners LOW,HIGH in Hz (Butterworth, order {ORDER}, zero-phase); "
                              "surface EMG lies in about 20-450 Hz")
    lowpass: float = Field(LOWPASS, gt=0, description=f"Envelope low-pass cut-off after full-wave rectification, Hz "
                           f"(Butterworth, order {ORDER}, zero-phase); synergy studies use 4-10 Hz")
    mvc: str | None = Field(None, description="A CSV with the EMG file's header and one row: each muscle's MVC "
                            "envelope value (band-passed, rectified, low-passed, in the EMG's units) to normalize by "
                            "(default: each muscle's largest envelope value)")
    downsample: float = Field(DOWNSAMPLE, gt=0, description="The envelopes' rate, Hz, resampled after the low-pass "
                              "(never above --rate: give --rate's value to keep every sample)")

    @field_validator("band")
    @classmethod
    def _ordered(cls, band: list[float]) -> list[float]:
        if not 0 < band[0] < band[1]:
            raise ValueError(f"give LOW,HIGH in Hz with 0 < LOW < HIGH, e.g. {BAND[0]:g},{BAND[1]:g}")
        return band


class ImportEmgSummary(Summary):
    file: str
    samples: int
    n_muscles: int
    names: list[str]
    trials: int
    rate: float  # the envelopes' rate, Hz
    recorded_rate: float
    recorded_samples: int
    normalization: str  # max or mvc
    clipped: int  # envelope values set to 0 or 1 (the low-pass's undershoot, values above an MVC)
    signal: str = EMG


class ImportEmgKind(StepKind[ImportEmgSettings, ImportEmgSummary]):
    """Import raw EMG (a CSV, one column per muscle) as normalized envelopes in activations.npz.

    Per trial: band-pass, full-wave rectify, low-pass (Butterworth filters run forward and backward,
    scipy.signal.sosfiltfilt), resample to --downsample; then each muscle divided by its largest
    envelope value, or by its MVC value (--mvc), and clipped to [0, 1]. `synergies vaf` and `fit` read
    the file as they read collected activations; its trials are the episodes cross-validation holds out."""

    name = "import-emg"
    what = "import EMG {file} ({rate:g} Hz)"
    headline_keys = ("samples", "n_muscles", "trials", "rate", "recorded_rate", "normalization", "clipped")
    metrics = (Metric("n_muscles", "muscles", "count"),
               Metric("trials", "trials", "count"),
               Metric("samples", "samples", "count"),
               Metric("rate", "envelope rate (Hz)"),
               Metric("recorded_rate", "recorded rate (Hz)", setup=True))
    command = "synergies import-emg"
    provides = Artifact("activations", ACTIVATIONS)
    arguments = ("file",)
    examples = ("motorlab synergies import-emg walking.csv --rate 2000 --out runs/emg",
                "motorlab synergies import-emg walking.csv --rate 2000 --mvc mvc.csv --band 20,450 --lowpass 6",
                "motorlab synergies fit runs/emg/activations.npz --n 4 --method nmf")

    def run(self, settings: ImportEmgSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> ImportEmgSummary:
        from motorlab.synergies.emg import EnvelopeFilters, import_emg

        s = settings
        filters = EnvelopeFilters(band=(s.band[0], s.band[1]), lowpass=s.lowpass, downsample=s.downsample)
        env = import_emg(Path(s.file), s.rate, filters, None if s.mvc is None else Path(s.mvc))
        self.refuse_finished_out(out)
        run_dir = self.start(out)
        meta = {"source_file": str(Path(s.file).resolve()), "recorded_rate": env.recorded_rate, "rate": env.rate,
                "recorded_samples": env.recorded_samples,
                "filters": {"band_hz": list(filters.band), "lowpass_hz": filters.lowpass, "order": filters.order,
                            "type": "butterworth", "zero_phase": True, "rectify": "full-wave",
                            "downsample_hz": filters.downsample},
                "normalization": env.normalization,
                "mvc_file": None if s.mvc is None else str(Path(s.mvc).resolve()),
                "scale": [float(v) for v in env.scale], "clipped": env.clipped,
                "trials": list(env.trials), "signal": EMG}
        n = len(env.names)
        # the layout save_activations writes (motorlab.synergy_runs.activations), so load_activations reads it
        atomic_write_npz(run_dir / ACTIVATIONS, activations=env.activations, names=np.array(env.names, dtype=str),
                         episode=env.episode, signal=np.array(EMG), low=np.zeros(n), high=np.ones(n),
                         metadata=np.array(json.dumps(meta)))
        summary = ImportEmgSummary(file=s.file, samples=len(env.activations), n_muscles=n, names=list(env.names),
                                   trials=len(env.trials), rate=env.rate, recorded_rate=env.recorded_rate,
                                   recorded_samples=env.recorded_samples, normalization=env.normalization,
                                   clipped=env.clipped)
        return self.finish(run_dir, settings, summary)

    def report(self, s: ImportEmgSummary, settings: ImportEmgSettings, console: Console) -> None:
        norm = "each muscle's maximum" if s.normalization == "max" else "MVC"
        console.print(f"{s.trials} trial{'s' if s.trials > 1 else ''}, {s.recorded_samples:,} samples at "
                      f"{s.recorded_rate:g} Hz -> {s.samples:,} envelope samples at {s.rate:g} Hz x {s.n_muscles} "
                      f"muscles, normalized to {norm} -> {s.run_dir}/{ACTIVATIONS}", soft_wrap=True)
        if s.clipped:
            console.print(f"{s.clipped:,} envelope values clipped to [0, 1] (below 0: the low-pass's undershoot"
                          + ("; above 1: above the MVC)" if s.normalization == "mvc" else ")"), soft_wrap=True)


IMPORT_EMG = ImportEmgKind()
