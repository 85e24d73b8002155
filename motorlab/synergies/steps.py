"""The synergy step kinds: `collect` muscle activations (or a robot's actuator controls, or an
env's actions) from a policy's good episodes, measure the `vaf` of N synergies, `fit` a
Synergistic Action Representation (sar.npz)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field
from rich.console import Console
from rich.table import Table

from motorlab.errors import MotorlabError
from motorlab.evaluation.activations import ACTIVATIONS, collect, load_activations, save_activations
from motorlab.report.results import Metric, Number
from motorlab.settings import MAX_SEED, Settings, Summary
from motorlab.stepkind import Artifact, Ref, StepKind, warn_faults
from motorlab.synergies.sar import fit_sar, require_sklearn, save_sar, smallest_n, vaf_curve

SAR_FILE = "sar.npz"

# ---- collect ----------------------------------------------------------------------------------


class CollectSettings(Settings):
    run: str = Field(description="A training run folder (the play policy)")
    episodes: int = Field(100, gt=0, description="Episodes to keep (those at or above the threshold)")
    percentile: float = Field(80.0, ge=0, le=100, description="Return threshold: this percentile of the preview "
                              "returns")
    preview: int = Field(50, gt=0, description="Preview episodes that set the threshold")
    deterministic: bool = Field(False, description="Act with the policy's mean instead of sampling from it")
    workers: int | None = Field(None, gt=0, description="Processes (default: all cores)")
    max_episodes: int | None = Field(None, gt=0, description="Give up after this many episodes past the preview "
                                     "(default: 20 x episodes)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (episode seeds and sampled actions)")
    signal: Literal["auto", "act", "ctrl", "action"] = Field(
        "auto", description="What to record: act (MuJoCo's muscle activations, data.act, in [0, 1]), ctrl (the "
        "actuator controls MuJoCo applied, data.ctrl clamped to its ctrlrange: a robot's motor commands), action "
        "(the env's action, for an env without MuJoCo), or auto (act where the model has activation states, "
        "else ctrl, else action)")


class CollectSummary(Summary):
    env_id: str
    samples: int
    n_muscles: int  # the size of the recorded signal, whatever it is (kept under its first name)
    signal: str = "act"
    n_signals: int = 0
    episodes_kept: int
    episodes_requested: int
    episodes_tried: int
    threshold: float
    preview_return_mean: float
    kept_return_mean: float
    kept_success_rate: float
    numerical_faults: int


class CollectKind(StepKind[CollectSettings, CollectSummary]):
    """Record the muscle activations, actuator controls or actions of a policy's good episodes.

    What is recorded (--signal; auto picks the first the env has): MuJoCo's muscle activations
    (data.act), actuator controls (data.ctrl) or the env's actions, to activations.npz. Preview episodes set a return threshold at the P-th percentile; then episodes run until N
    of them reach it. Episodes run in a process pool, each from its own seed, so the result does
    not depend on the number of workers."""

    name = "collect"
    what = "collect {episodes} episodes from {run} (≥ {percentile:g}th pct.)"
    headline_keys = ("signal", "samples", "n_muscles", "episodes_kept", "episodes_requested", "episodes_tried", "threshold",
                     "kept_return_mean", "kept_success_rate")
    metrics = (Metric("episodes_kept", "episodes kept", "count", of="episodes_requested"),
               Metric("samples", "samples", "count"),
               Metric("n_muscles", "muscles", "count"),
               Metric("threshold", "return threshold", "return"),
               Metric("kept_return_mean", "kept episodes' return", "return"),
               Metric("kept_success_rate", "kept episodes' success", "percent"),
               Metric("episodes_tried", "episodes run", "count", setup=True))
    command = "synergies collect"
    refs = (Ref("run", ("policy",)),)
    provides = Artifact("activations", ACTIVATIONS)
    arguments = ("run",)
    examples = ("motorlab synergies collect runs/play --episodes 1000 --percentile 80 --preview 100",)

    def run(self, settings: CollectSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> CollectSummary:
        s = settings
        c = collect(Path(s.run), s.episodes, s.percentile, s.preview, s.seed, s.deterministic, s.workers,
                    s.max_episodes, progress, s.signal, before_work=lambda: self.refuse_finished_out(out))
        run_dir = self.start(out)
        acts = c.activations()
        meta = {"source_run": str(c.source_run.resolve()), "env_id": c.env_id, "percentile": s.percentile,
                "preview": s.preview, "deterministic": s.deterministic, "seed": s.seed,
                "episodes_requested": s.episodes, "episodes_tried": c.tried, "signal_requested": s.signal}
        save_activations(run_dir / ACTIVATIONS, c, meta)
        summary = CollectSummary(
            env_id=c.env_id, samples=len(acts), n_muscles=acts.shape[1], signal=c.signal, n_signals=acts.shape[1],
            episodes_kept=len(c.kept),
            episodes_requested=s.episodes, episodes_tried=c.tried, threshold=c.threshold,
            preview_return_mean=float(c.preview_returns.mean()),
            kept_return_mean=float(np.mean([e.ret for e in c.kept])),
            kept_success_rate=float(np.mean([e.solved for e in c.kept])), numerical_faults=len(c.fault_log))
        return self.finish(run_dir, settings, summary, c.fault_log)

    def numbers(self, settings: CollectSettings, h: dict[str, Any]) -> list[Number]:
        return [_size_label(n, h.get("signal")) for n in super().numbers(settings, h)]

    def report(self, s: CollectSummary, settings: CollectSettings, console: Console) -> None:
        what = {"act": "muscle activations", "ctrl": "actuator controls", "action": "action elements"}[s.signal]
        console.print(f"kept {s.episodes_kept} episodes (return >= {s.threshold:.3g}), {s.samples:,} samples "
                      f"x {s.n_signals} {what} ({s.signal}) -> {s.run_dir}/activations.npz")
        warn_faults(s)


def _size_label(n: Number, signal: str | None) -> Number:
    """The signal's size as readers name it: muscles, actuators or action dimensions."""
    if n.key != "n_muscles" or signal in (None, "act"):
        return n
    return Number(n.key, "actuators" if signal == "ctrl" else "action dimensions", n.value, n.text, n.setup)


COLLECT = CollectKind()


# ---- vaf --------------------------------------------------------------------------------------


class VafSettings(Settings):
    activations: str = Field(description="activations.npz (or its folder)")
    threshold: float = Field(0.8, gt=0, le=1, description="Report the smallest N whose VAF reaches this")
    method: Literal["pca", "pca-ica", "nmf"] = Field("pca", description="pca (also pca-ica: same VAF) or nmf "
                                                     "(classic, uncentered)")
    max_n: int | None = Field(None, gt=0, description="Largest N (saves time with nmf)")


class VafSummary(Summary):
    method: str
    n_muscles: int
    samples: int
    threshold: float
    n_for_threshold: int | None
    vaf: list[float]
    signal: str = "act"



def _import_sklearn() -> None:
    """scikit-learn, imported whole in the calling thread (StepKind.warm_up): sklearn imports
    narwhals, whose modules import each other in a circle; a study's background thread importing
    it beside this one failed once with Python's import _DeadlockError (CI, sar-hand-quick)."""
    require_sklearn()
    import sklearn.decomposition  # noqa: F401
    import sklearn.preprocessing  # noqa: F401


class VafKind(StepKind[VafSettings, VafSummary]):
    """Variance accounted for by N = 1..n_muscles synergies: vaf.png and the smallest N reaching the threshold."""

    name = "vaf"
    what = "VAF of {activations} ({method})"
    key_figures = ("vaf.png",)
    headline_keys = ("n_for_threshold", "threshold", "n_muscles", "signal")
    metrics = (Metric("n_muscles", "muscles", "count"),)
    command = "synergies vaf"
    refs = (Ref("activations", ("activations",)),)
    arguments = ("activations",)
    examples = ("motorlab synergies vaf runs/collect/activations.npz --threshold 0.8",)

    def warm_up(self) -> None:
        _import_sklearn()

    def run(self, settings: VafSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> VafSummary:
        from motorlab.report.plots import vaf_plot

        acts, meta = load_activations(Path(settings.activations))
        curve = vaf_curve(acts, method=settings.method, max_n=settings.max_n)
        try:
            n_needed: int | None = smallest_n(curve, settings.threshold)
        except MotorlabError:
            n_needed = None  # reported as null; the curve is still worth having
        run_dir = self.start(out)
        what = {"act": "activations", "ctrl": "actuator controls", "action": "actions"}.get(meta["signal"], "signals")
        vaf_plot(curve, settings.threshold, n_needed, run_dir / "vaf.png",
                 f"VAF of {meta.get('env_id', 'recorded')} {what} ({settings.method})")
        summary = VafSummary(method=settings.method, n_muscles=acts.shape[1], samples=acts.shape[0],
                             threshold=settings.threshold, n_for_threshold=n_needed, vaf=[float(v) for v in curve],
                             signal=meta["signal"])
        return self.finish(run_dir, settings, summary)

    def numbers(self, settings: VafSettings, h: dict[str, Any]) -> list[Number]:
        n = h["n_for_threshold"]
        label = f"synergies for VAF ≥ {h['threshold']:.0%}"
        return [Number("n_for_threshold", label, n, f"{n}" if n else "none reaches it"),
                *(_size_label(x, h.get("signal")) for x in super().numbers(settings, h))]

    def metric(self, key: str) -> Metric:
        return Metric(key, "synergies for the VAF threshold", "count") if key == "n_for_threshold" else super().metric(key)

    def report(self, s: VafSummary, settings: VafSettings, console: Console) -> None:
        table = Table(title=f"VAF ({s.method}), {s.samples:,} samples x {s.n_muscles} muscles")
        table.add_column("N", justify="right")
        table.add_column("VAF", justify="right")
        for n, v in enumerate(s.vaf, 1):
            table.add_row(str(n), f"{v:.1%}" + (" <-" if n == s.n_for_threshold else ""))
        console.print(table)
        need = s.n_for_threshold
        console.print(f"smallest N with VAF >= {settings.threshold:.0%}: {need if need is not None else 'none'}; "
                      f"written: {s.run_dir}/vaf.png")


VAF = VafKind()


# ---- fit --------------------------------------------------------------------------------------


class FitSettings(Settings):
    activations: str = Field(description="activations.npz (or its folder)")
    n_synergies: int | None = Field(None, gt=0, description="Number of synergies N")
    vaf: float | None = Field(None, gt=0, le=1, description="Or: the smallest N whose VAF reaches this, e.g. 0.8")
    method: Literal["pca-ica", "pca", "nmf"] = Field("pca-ica", description="pca-ica (PCA -> FastICA -> scale to "
                                                     "[-1,1], the reference), pca, or nmf")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (FastICA, NMF)")


class FitSummary(Summary):
    sar: str
    method: str
    n_synergies: int
    n_muscles: int  # the size of the signal it decodes to
    vaf: float | None
    source_env: str | None
    samples: int
    signal: str = "act"


class FitKind(StepKind[FitSettings, FitSummary]):
    """Fit a Synergistic Action Representation; writes sar.npz (plain arrays + JSON metadata, no pickle)."""

    name = "fit"
    headline_keys = ("n_synergies", "n_muscles", "vaf", "signal")
    metrics = (Metric("n_synergies", "synergies", "count"),
               Metric("vaf", "VAF", "percent"),
               Metric("n_muscles", "muscles", "count"))
    findings = ("n_synergies", "vaf")
    command = "synergies fit"
    refs = (Ref("activations", ("activations",)),)
    provides = Artifact("sar", SAR_FILE)
    arguments = ("activations",)
    flags = {"n_synergies": ("--n-synergies", "--n")}
    examples = ("motorlab synergies fit activations.npz --vaf 0.8",
                "motorlab synergies fit activations.npz --n 20 --method nmf")

    def warm_up(self) -> None:
        _import_sklearn()

    def run(self, settings: FitSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> FitSummary:
        acts, meta = load_activations(Path(settings.activations))
        self.refuse_finished_out(out)
        sar = fit_sar(acts, n_synergies=settings.n_synergies, vaf=settings.vaf, method=settings.method,
                      seed=settings.seed, source_env=meta.get("env_id"), signal=meta["signal"],
                      bounds=(meta["low"], meta["high"]))
        run_dir = self.start(out)
        save_sar(sar, run_dir / SAR_FILE)
        summary = FitSummary(sar=str(run_dir / SAR_FILE), method=settings.method, n_synergies=sar.n_synergies,
                             n_muscles=sar.n_muscles, vaf=sar.metadata.get("vaf"), source_env=meta.get("env_id"),
                             samples=acts.shape[0], signal=meta["signal"])
        return self.finish(run_dir, settings, summary)

    def numbers(self, settings: FitSettings, h: dict[str, Any]) -> list[Number]:
        return [_size_label(n, h.get("signal")) for n in super().numbers(settings, h)]

    def describe(self, settings: FitSettings, copies: int = 1) -> str:
        return (f"fit {settings.method} to {settings.activations}"
                + (f", N = {settings.n_synergies}" if settings.n_synergies else f", VAF ≥ {settings.vaf}"))

    def report(self, s: FitSummary, settings: FitSettings, console: Console) -> None:
        console.print(f"{s.n_synergies} synergies ({s.method}) for {s.n_muscles} muscles, VAF {s.vaf:.1%} -> {s.sar}")


FIT = FitKind()
