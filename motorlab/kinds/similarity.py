"""`synergies compare A B`: how alike two synergy sets are, pair by pair, against a shuffled-data null
(motorlab.synergies.similarity): play task vs target task, seed vs seed, simulation vs EMG."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import Field
from rich.console import Console
from rich.table import Table

from motorlab.errors import MotorlabError
from motorlab.kinds.synergies import _import_sklearn
from motorlab.report.results import Metric
from motorlab.settings import MAX_SEED, Settings, Summary
from motorlab.stepkind import Ref, StepKind

NULL_PERCENTILE = 95


class CompareSettings(Settings):
    a: str = Field(description="The first synergy set: a sar.npz, or a `synergies fit` run folder")
    b: str = Field(description="The second: a sar.npz or a fit run folder; the null re-fits its method and N")
    activations: str | None = Field(None, description="The activations the null shuffles (default: those B was "
                                    "fitted to, from B's fit run folder)")
    surrogates: int = Field(100, ge=10, description="Shuffled surrogates for the chance level")
    max_samples: int | None = Field(None, gt=100, description=(
        "Samples each surrogate fit uses, a random draw (default: all, as many as B's fit saw). Fewer is faster but "
        "lowers the chance level: a fit to fewer shuffled samples lands farther from any synergy set, so more pairs "
        "look above chance (measured: the synergy_analysis benchmark)"))
    names_from: str | None = Field(None, description="An env id whose MuJoCo actuator names label a SAR saved "
                                   "without muscle names (MyoSuite's published SARs)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (shuffles, the surrogates' fits)")
    workers: int | None = Field(None, gt=0, description="Processes for the surrogates (default: all cores)")


class PairRow(Summary):
    a: int  # synergy index in A (0-based)
    b: int  # its match in B
    similarity: float
    above_chance: bool


class CompareSummary(Summary):
    n_a: int
    n_b: int
    n_muscles: int
    method_b: str
    absolute: bool  # |cos| (PCA / ICA directions have no sign) or cos (NMF)
    pairs: list[PairRow]
    similarity_mean: float
    chance_pair_p95: float  # the 95th percentile of matched pairs' cosines over the surrogates
    chance_mean_p95: float  # ... of the surrogates' mean matched cosine
    mean_above_chance: bool
    pairs_above_chance: int
    surrogates: int
    surrogate_samples: int
    names_from: str  # "saved" or the env id they were read from


class CompareKind(StepKind[CompareSettings, CompareSummary]):
    """Match two synergy sets one to one and test each pair against a shuffled-data chance level.

    Pairs: cosine of the muscle weights, the Hungarian assignment. Chance: B's activations with each muscle
    shuffled in time, re-fitted (B's method and N) --surrogates times; a pair above the surrogates' 95th
    percentile is more alike than chance makes. Muscles are matched by name (the body's actuator names); sets
    over different muscles are refused. Writes similarity.png and the pairs."""

    name = "similarity"
    what = "compare synergies {a} and {b}"
    key_figures = ("similarity.png",)
    headline_keys = ("similarity_mean", "chance_pair_p95", "pairs_above_chance", "n_a", "n_b")
    metrics = (Metric("similarity_mean", "mean matched cosine", "number"),
               Metric("chance_pair_p95", "chance (95th pct.)", "number"),
               Metric("pairs_above_chance", "pairs above chance", "count"))
    findings = ("similarity_mean", "pairs_above_chance")
    command = "synergies compare"
    refs = (Ref("a", ("sar",)), Ref("b", ("sar",)))
    arguments = ("a", "b")
    examples = ("motorlab synergies compare runs/fit-play runs/fit-target",
                "motorlab synergies compare runs/fit published-sar.npz --names-from myoHandReorient8-v0 "
                "--activations runs/collect")

    def warm_up(self) -> None:
        _import_sklearn()

    def run(self, settings: CompareSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> CompareSummary:
        from motorlab.synergies.sar import load_sar
        from motorlab.synergies.similarity import aligned, chance, match
        from motorlab.synergies.vectors import vectors_of
        from motorlab.synergy_runs.activations import load_activations
        from motorlab.synergy_runs.naming import fitted_activations, names_for, sar_file

        a, b = load_sar(sar_file(settings.a)), load_sar(sar_file(settings.b))
        names_a, from_a = names_for(a, settings.names_from, "A")
        names_b, from_b = names_for(b, settings.names_from, "B")
        order = aligned(names_a, names_b)  # B's columns in A's muscle order; refuses other muscles
        source = Path(settings.activations) if settings.activations else fitted_activations(settings.b)
        if source is None:
            raise MotorlabError("the chance level needs the activations B was fitted to: give --activations "
                                "(an activations.npz or its folder).")
        acts, meta = load_activations(source)
        if acts.shape[1] != b.n_muscles:
            raise MotorlabError(f"--activations has {acts.shape[1]} signals and B decodes to {b.n_muscles}: give the "
                                "activations B was fitted to.")
        method = b.method if b.method in ("pca-ica", "pca", "nmf") else "pca-ica"  # an imported SAR: PCA -> ICA
        absolute = method != "nmf" or a.method != "nmf"
        self.refuse_finished_out(out)
        wa = vectors_of(a).normalized
        wb = vectors_of(b).normalized[:, order]
        matched = match(wa, wb, absolute)
        null = chance(wa, acts[:, order], method, b.n_synergies, settings.surrogates, settings.seed,
                      settings.max_samples, settings.workers)
        run_dir = self.start(out)
        p95 = null.p95
        pairs = [PairRow(a=i, b=j, similarity=s, above_chance=s > p95)
                 for (i, j), s in zip(matched.pairs, matched.similarity)]
        _plot(pairs, p95, names_a, wa, wb, run_dir / "similarity.png",
              f"{Path(settings.a).name} vs {Path(settings.b).name} ({'|cos|' if absolute else 'cos'})")
        summary = CompareSummary(n_a=a.n_synergies, n_b=b.n_synergies, n_muscles=a.n_muscles, method_b=method,
                                 absolute=absolute, pairs=pairs, similarity_mean=matched.mean, chance_pair_p95=p95,
                                 chance_mean_p95=null.mean_p95, mean_above_chance=matched.mean > null.mean_p95,
                                 pairs_above_chance=sum(p.above_chance for p in pairs), surrogates=null.surrogates,
                                 surrogate_samples=null.samples,
                                 names_from="saved" if from_a == from_b == "saved" else settings.names_from or "saved")
        return self.finish(run_dir, settings, summary)

    def report(self, s: CompareSummary, settings: CompareSettings, console: Console) -> None:
        table = Table(title=f"matched synergies ({'|cos|' if s.absolute else 'cos'}), chance: 95th percentile of "
                            f"{s.surrogates} shuffled surrogates = {s.chance_pair_p95:.3f}")
        for column in ("A", "B", "similarity", "above chance"):
            table.add_column(column, justify="right")
        for p in s.pairs:
            table.add_row(f"S{p.a + 1}", f"S{p.b + 1}", f"{p.similarity:.3f}", "yes" if p.above_chance else "no")
        console.print(table)
        console.print(f"mean {s.similarity_mean:.3f} (chance's 95th percentile of the mean: {s.chance_mean_p95:.3f}); "
                      f"{s.pairs_above_chance} of {len(s.pairs)} pairs above chance; written: {s.run_dir}/similarity.png")


def _plot(pairs: list[PairRow], p95: float, names: list[str], wa: np.ndarray, wb: np.ndarray, path: Path,
          title: str) -> Path | None:
    """Each matched pair's similarity against the chance level, beside the two sets' weights side by side."""
    from motorlab.report.plots import STYLE, plt, save_figure

    with plt.rc_context(STYLE):
        fig, (bars, weights) = plt.subplots(1, 2, figsize=(11, 1.2 + 0.22 * max(len(names), 8)),
                                            gridspec_kw={"width_ratios": [1, 2]})
        labels = [f"A{p.a + 1}-B{p.b + 1}" for p in pairs]
        bars.barh(labels, [p.similarity for p in pairs],
                  color=["tab:green" if p.above_chance else "tab:gray" for p in pairs])
        bars.axvline(p95, color="tab:red", ls="--", lw=1, label=f"chance (95th pct.) {p95:.2f}")
        bars.set_xlim(0, 1)
        bars.invert_yaxis()
        bars.set_xlabel("cosine similarity")
        bars.legend(loc="lower right", fontsize=7)
        side = np.concatenate([np.column_stack([wa[p.a], wb[p.b]]) for p in pairs], axis=1)
        limit = float(np.abs(side).max()) or 1.0
        weights.imshow(side, aspect="auto", cmap="RdBu_r", vmin=-limit, vmax=limit, interpolation="nearest")
        weights.set_yticks(range(len(names)), names, fontsize=6)
        weights.set_xticks(range(side.shape[1]), [f"{w}{p.a + 1 if w == 'A' else p.b + 1}" for p in pairs
                                                  for w in ("A", "B")], fontsize=6)
        weights.grid(False)
        weights.set_title("matched weights, side by side", fontsize=8)
        fig.suptitle(title, fontsize=9)
        return save_figure(fig, path, f"{len(pairs)} matched synergy pairs; {sum(p.above_chance for p in pairs)} above "
                                      f"the shuffled-data chance level {p95:.2f}.")


SIMILARITY = CompareKind()
