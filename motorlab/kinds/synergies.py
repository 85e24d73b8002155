"""The synergy step kinds: `collect` muscle activations (or a robot's actuator controls, or an
env's actions) from a policy's good episodes, measure the `vaf` of N synergies, `fit` a
Synergistic Action Representation (sar.npz)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator
from rich.console import Console
from rich.table import Table

from motorlab.errors import MotorlabError
from motorlab.report.results import Metric, Number
from motorlab.settings import MAX_SEED, Settings, Summary
from motorlab.stepkind import Artifact, Ref, StepKind, warn_faults
from motorlab.synergies.sar import check_nmf_input, fit_sar, require_sklearn, save_sar
from motorlab.synergy_runs.activations import ACTIVATIONS, collect, load_activations, save_activations
from motorlab.synergy_runs.naming import SAR_FILE  # the fit folder's file, named once

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


def signal_words(signal: str) -> str:
    """What a recorded signal is, in words, for titles."""
    return {"act": "activations", "ctrl": "actuator controls", "action": "actions",
            "emg": "EMG envelopes"}.get(signal, "signals")


def _size_label(n: Number, signal: str | None) -> Number:
    """The signal's size as readers name it: muscles, actuators or action dimensions."""
    if n.key != "n_muscles" or signal in (None, "act", "emg"):  # emg: envelopes of recorded muscles (import-emg)
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
    cv: int | None = Field(None, ge=2, description="Cross-validate: fit on K-1 folds of episodes, score the held-out "
                           "fold; the curve is the folds' mean, with their spread (default: in-sample, one fit)")
    muscle_threshold: float = Field(0.75, gt=0, le=1, description="Also report the smallest N at which every "
                                    "muscle's own VAF reaches this")
    workers: int | None = Field(None, gt=0, description="Processes for the fits (default: all cores)")


class VafSummary(Summary):
    method: str
    n_muscles: int
    samples: int
    threshold: float
    n_for_threshold: int | None
    vaf: list[float]  # the curve (held out: the folds' mean)
    signal: str = "act"
    vaf_definition: str = "centred"  # uncentred (NMF) or centred (PCA)
    cv_folds: int = 0  # 0: in-sample
    vaf_std: list[float] = []  # over folds (zeros in-sample)
    muscle_threshold: float = 0.75
    n_by_muscle_vaf: int | None = None
    n_by_elbow: int | None = None
    names: list[str] = []
    muscle_vaf: list[list[float]] = []  # (N, muscles): each muscle's VAF (held out: the folds' mean)
    vaf_folds: list[list[float]] = []  # (folds, N): each fold's held-out VAF (in-sample: one row)
    vaf_train: list[list[float]] = []  # (folds, N): the VAF on the folds each fit was fitted on



def _import_sklearn() -> None:
    """scikit-learn, imported whole in the calling thread (StepKind.warm_up): sklearn imports
    narwhals, whose modules import each other in a circle; a study's background thread importing
    it beside this one failed once with Python's import _DeadlockError (CI, sar-hand-quick)."""
    require_sklearn()
    import sklearn.decomposition  # noqa: F401
    import sklearn.preprocessing  # noqa: F401


class VafKind(StepKind[VafSettings, VafSummary]):
    """Variance accounted for by N = 1..n_muscles synergies, and the N each criterion chooses.

    In-sample, or cross-validated over episodes (--cv K: fit on K-1 folds, score the held-out one). Criteria:
    total VAF (--threshold), every muscle's own VAF (--muscle-threshold), the curve's elbow (d'Avella et al.
    2003: a line fits the rest of the curve with MSE < 1e-4). NMF's VAF is uncentred (1 - SSE / sum x^2),
    PCA's centred (explained variance); vaf.png and the table say which."""

    name = "vaf"
    what = "VAF of {activations} ({method})"
    key_figures = ("vaf.png",)
    headline_keys = ("n_for_threshold", "threshold", "n_muscles", "signal")
    metrics = (Metric("n_muscles", "muscles", "count"),)
    command = "synergies vaf"
    refs = (Ref("activations", ("activations",)),)
    arguments = ("activations",)
    examples = ("motorlab synergies vaf runs/collect/activations.npz --threshold 0.8",
                "motorlab synergies vaf runs/collect --method nmf --cv 5 --max-n 20 --threshold 0.9")

    def warm_up(self) -> None:
        _import_sklearn()

    def run(self, settings: VafSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> VafSummary:
        from motorlab.synergies.analysis import choices, cross_validated_vaf
        from motorlab.synergy_runs.figures import vaf_with_band

        acts, meta = load_activations(Path(settings.activations))
        if settings.method == "nmf":
            check_nmf_input(acts)  # negative or all-zero activations: NMF's one-line refusal, before any fit
        self.refuse_finished_out(out)
        cv = cross_validated_vaf(acts, meta["episode"], settings.method, settings.max_n, settings.cv,
                                 workers=settings.workers)
        chosen = choices(cv, settings.threshold, settings.muscle_threshold)
        run_dir = self.start(out)
        vaf_with_band(cv, chosen, run_dir / "vaf.png",
                      f"VAF of {meta.get('env_id', 'recorded')} {signal_words(meta['signal'])} ({settings.method})")
        by = {c.criterion: c.n for c in chosen}
        summary = VafSummary(method=settings.method, n_muscles=acts.shape[1], samples=acts.shape[0],
                             threshold=settings.threshold, n_for_threshold=by["total-vaf"],
                             vaf=[float(v) for v in cv.mean], signal=meta["signal"], vaf_definition=cv.definition,
                             cv_folds=cv.folds, vaf_std=[float(v) for v in cv.std],
                             muscle_threshold=settings.muscle_threshold, n_by_muscle_vaf=by["muscle-vaf"],
                             n_by_elbow=by["elbow"], names=meta["names"],
                             muscle_vaf=[[round(float(v), 6) for v in row] for row in cv.muscle_mean],
                             vaf_folds=cv.total.tolist(), vaf_train=cv.train.tolist())
        return self.finish(run_dir, settings, summary)

    def numbers(self, settings: VafSettings, h: dict[str, Any]) -> list[Number]:
        n = h["n_for_threshold"]
        label = f"synergies for VAF ≥ {h['threshold']:.0%}"
        return [Number("n_for_threshold", label, n, f"{n}" if n else "none reaches it"),
                *(_size_label(x, h.get("signal")) for x in super().numbers(settings, h))]

    def metric(self, key: str) -> Metric:
        return Metric(key, "synergies for the VAF threshold", "count") if key == "n_for_threshold" else super().metric(key)

    def report(self, s: VafSummary, settings: VafSettings, console: Console) -> None:
        how = f"held out, {s.cv_folds} folds of episodes" if s.cv_folds else "in-sample"
        table = Table(title=f"VAF ({s.method}, {s.vaf_definition}, {how}), {s.samples:,} samples x {s.n_muscles} muscles")
        table.add_column("N", justify="right")
        table.add_column("VAF", justify="right")
        if s.cv_folds:
            table.add_column("SD over folds", justify="right")
        table.add_column("lowest muscle VAF", justify="right")
        for n, v in enumerate(s.vaf, 1):
            lowest = min(s.muscle_vaf[n - 1]) if s.muscle_vaf else float("nan")
            tag = ", ".join(k for m, k in ((s.n_for_threshold, "total"), (s.n_by_muscle_vaf, "muscles"),
                                           (s.n_by_elbow, "elbow")) if m == n)
            table.add_row(str(n), f"{v:.1%}" + (f" <- {tag}" if tag else ""),
                          *([f"{s.vaf_std[n - 1]:.1%}"] if s.cv_folds else []), f"{lowest:.1%}")
        console.print(table)

        def said(n: int | None) -> str:
            return str(n) if n is not None else "none"

        console.print(f"N by total VAF >= {s.threshold:.0%}: {said(s.n_for_threshold)}; by every muscle's VAF >= "
                      f"{s.muscle_threshold:.0%}: {said(s.n_by_muscle_vaf)}; by the elbow: {said(s.n_by_elbow)}; "
                      f"written: {s.run_dir}/vaf.png")


VAF = VafKind()


# ---- fit --------------------------------------------------------------------------------------


class FitSettings(Settings):
    activations: str = Field(description="activations.npz (or its folder)")
    n_synergies: int | None = Field(None, gt=0, description="Number of synergies N")
    vaf: float | None = Field(None, gt=0, le=1, description="Or: the smallest N whose total VAF reaches this, e.g. 0.8")
    muscle_vaf: float | None = Field(None, gt=0, le=1, description="Or: the smallest N at which every muscle's own VAF "
                                     "reaches this, e.g. 0.75")
    elbow: bool = Field(False, description="Or: N at the VAF curve's elbow (a line fits the rest of the curve with MSE "
                        "< 1e-4, d'Avella et al. 2003)")
    cv: int | None = Field(None, ge=2, description="Choose N on VAF held out over K folds of episodes (default: "
                           "in-sample)")
    max_n: int | None = Field(None, gt=0, description="Largest N a criterion considers (saves time with nmf)")
    method: Literal["pca-ica", "pca", "nmf"] = Field("pca-ica", description="pca-ica (PCA -> FastICA -> scale to "
                                                     "[-1,1], the reference), pca, or nmf")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (FastICA, NMF)")
    workers: int | None = Field(None, gt=0, description="Processes for the criterion's fits (default: all cores)")

    @model_validator(mode="after")
    def _one_way_to_n(self):
        given = [k for k, v in (("--n-synergies", self.n_synergies), ("--vaf", self.vaf), ("--muscle-vaf", self.muscle_vaf),
                                ("--elbow", self.elbow or None)) if v is not None]
        if len(given) > 1:  # none given is refused when it runs: a recipe may set N in a later layer
            raise MotorlabError(f"give exactly one way to choose N: --n-synergies (--n), --vaf, --muscle-vaf or "
                                f"--elbow (given: {', '.join(given)}).")
        return self


class FitSummary(Summary):
    sar: str
    method: str
    n_synergies: int
    n_muscles: int  # the size of the signal it decodes to
    vaf: float | None
    source_env: str | None
    samples: int
    signal: str = "act"
    chosen_by: str = "given"  # which criterion chose N, in words ("given": --n)
    names: list[str] = []


class FitKind(StepKind[FitSettings, FitSummary]):
    """Fit a Synergistic Action Representation; writes sar.npz (plain arrays + JSON metadata, no pickle).

    Beside it: the muscle-weight heatmap (muscles named as the model names its actuators), the synergies'
    activation coefficients over the first episodes, and, where a criterion chose N (--vaf with --cv,
    --muscle-vaf, --elbow), the VAF curve it chose on."""

    name = "fit"
    key_figures = ("heatmap.png", "coefficients.png", "vaf.png")
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
                "motorlab synergies fit activations.npz --n 20 --method nmf",
                "motorlab synergies fit activations.npz --method nmf --muscle-vaf 0.75 --cv 5 --max-n 20")

    def warm_up(self) -> None:
        _import_sklearn()

    def run(self, settings: FitSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> FitSummary:
        import motorlab.synergy_runs.figures as figures
        from motorlab.synergies.vectors import vectors_of

        if (settings.n_synergies, settings.vaf, settings.muscle_vaf, settings.elbow) == (None, None, None, False):
            raise MotorlabError("give one way to choose N: --n-synergies (--n), --vaf, --muscle-vaf or --elbow.")
        acts, meta = load_activations(Path(settings.activations))
        self.refuse_finished_out(out)
        n, vaf, cv, chosen = settings.n_synergies, settings.vaf, None, None
        if settings.muscle_vaf is not None or settings.elbow or (settings.vaf is not None and settings.cv):
            n, cv, chosen = _choose_n(acts, meta, settings)
            vaf = None
        sar = fit_sar(acts, n_synergies=n, vaf=vaf, method=settings.method, seed=settings.seed,
                      source_env=meta.get("env_id"), signal=meta["signal"], bounds=(meta["low"], meta["high"]),
                      names=meta["names"])
        chosen_by = (chosen.text if chosen is not None else
                     f"in-sample VAF ({'uncentred' if settings.method == 'nmf' else 'centred'}) >= {settings.vaf:g}"
                     if settings.vaf is not None else "given")
        run_dir = self.start(out)
        save_sar(sar, run_dir / SAR_FILE)
        where = f"{meta.get('env_id', 'recorded')} {signal_words(meta['signal'])}"
        figures.heatmap(vectors_of(sar), run_dir / "heatmap.png", f"{sar.n_synergies} synergies ({settings.method}) "
                        f"of {where}")
        shown = np.isin(meta["episode"], np.unique(meta["episode"])[:3])  # the first three episodes
        figures.coefficients(sar.encode(acts[shown]), meta["episode"][shown], run_dir / "coefficients.png",
                             f"synergy coefficients, {where}")
        if cv is not None:
            from motorlab.synergies.analysis import choices

            figures.vaf_with_band(cv, choices(cv, settings.vaf or 0.9, settings.muscle_vaf or 0.75),
                                  run_dir / "vaf.png", f"VAF of {where} ({settings.method}); N by {chosen.criterion}")
        summary = FitSummary(sar=str(run_dir / SAR_FILE), method=settings.method, n_synergies=sar.n_synergies,
                             n_muscles=sar.n_muscles, vaf=sar.metadata.get("vaf"), source_env=meta.get("env_id"),
                             samples=acts.shape[0], signal=meta["signal"], chosen_by=chosen_by, names=meta["names"])
        return self.finish(run_dir, settings, summary)

    def numbers(self, settings: FitSettings, h: dict[str, Any]) -> list[Number]:
        return [_size_label(n, h.get("signal")) for n in super().numbers(settings, h)]

    def describe(self, settings: FitSettings, copies: int = 1) -> str:
        how = (f"N = {settings.n_synergies}" if settings.n_synergies else f"VAF ≥ {settings.vaf}" if settings.vaf
               else f"every muscle's VAF ≥ {settings.muscle_vaf}" if settings.muscle_vaf else "N at the VAF elbow")
        return f"fit {settings.method} to {settings.activations}, {how}" + (f" ({settings.cv}-fold)" if settings.cv else "")

    def report(self, s: FitSummary, settings: FitSettings, console: Console) -> None:
        console.print(f"{s.n_synergies} synergies ({s.method}) for {s.n_muscles} muscles, VAF {s.vaf:.1%} -> {s.sar}; "
                      f"N chosen by: {s.chosen_by}")


def _choose_n(acts: np.ndarray, meta: dict[str, Any], settings: FitSettings):
    """N by the criterion `settings` names, on the in-sample or cross-validated curve: (N, curve, choice).

    Raises:
        MotorlabError: no N up to max_n meets the criterion."""
    from motorlab.synergies.analysis import choices, cross_validated_vaf

    if settings.method == "nmf":
        check_nmf_input(acts)  # negative or all-zero activations: NMF's one-line refusal, before any fit
    cv = cross_validated_vaf(acts, meta["episode"], settings.method, settings.max_n, settings.cv,
                             seed=settings.seed, workers=settings.workers)
    criterion = "muscle-vaf" if settings.muscle_vaf is not None else "elbow" if settings.elbow else "total-vaf"
    choice = next(c for c in choices(cv, settings.vaf or 0.9, settings.muscle_vaf or 0.75) if c.criterion == criterion)
    if choice.n is None:
        best = (f"the lowest muscle's best is {cv.muscle_mean.min(axis=1).max():.3f}" if criterion == "muscle-vaf"
                else f"the best is {cv.mean.max():.3f}")
        fix = {"total-vaf": "lower --vaf", "muscle-vaf": "lower --muscle-vaf", "elbow": "give --n or --vaf"}[criterion]
        raise MotorlabError(f"no N up to {len(cv.ns)} meets {choice.text} ({best}); {fix}, or raise --max-n.")
    return choice.n, cv, choice


FIT = FitKind()
