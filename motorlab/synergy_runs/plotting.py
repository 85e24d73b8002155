"""`synergies plot`: a synergy set's figures from its files (a sar.npz or fit run folder, the activations,
a vaf run), for a SAR fitted anywhere: motorlab's own, MyoSuite's published one, one fitted on EMG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motorlab.errors import MotorlabError


def plot_synergies(sar_path: Path, out: Path, activations: Path | None = None, vaf_run: Path | None = None,
                   episodes: int = 3, names_from: str | None = None) -> list[Path]:
    """heatmap.png, and coefficients.png / vaf.png where their inputs are there; the paths written."""
    import motorlab.synergy_runs.figures as figures
    from motorlab.runs import read_json
    from motorlab.synergies.analysis import Choice, CrossValidatedVaf, choices
    from motorlab.synergies.sar import load_sar
    from motorlab.synergies.vectors import SynergyVectors, vectors_of
    from motorlab.synergy_runs.activations import load_activations
    from motorlab.synergy_runs.naming import fitted_activations, names_for, sar_file

    sar = load_sar(sar_file(sar_path))
    names, _ = names_for(sar, names_from, "the SAR")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = [figures.heatmap(SynergyVectors(vectors_of(sar).weights, names, sar.method), out / "heatmap.png",
                               f"{sar.n_synergies} synergies ({sar.method}), {Path(sar_path).name}")]
    source = Path(activations) if activations else fitted_activations(sar_path)
    if source is not None:
        acts, meta = load_activations(source)
        if acts.shape[1] != sar.n_muscles:
            raise MotorlabError(f"--activations has {acts.shape[1]} signals and the SAR decodes to {sar.n_muscles}: "
                                "give the activations of the SAR's body.")
        shown = np.isin(meta["episode"], np.unique(meta["episode"])[:episodes])
        written.append(figures.coefficients(sar.encode(acts[shown]), meta["episode"][shown], out / "coefficients.png",
                                            "synergy coefficients"))
    if vaf_run is not None:
        s = read_json(Path(vaf_run) / "summary.json")
        if "vaf_folds" not in s:
            raise MotorlabError(f"{vaf_run} is not a `synergies vaf` run of this motorlab (no vaf_folds in its "
                                "summary.json); run `motorlab synergies vaf` again.")
        folds = np.asarray(s["vaf_folds"], dtype=np.float64)
        cv = CrossValidatedVaf(s["method"], s["vaf_definition"], s["cv_folds"], list(range(1, folds.shape[1] + 1)),
                               folds, np.asarray(s["muscle_vaf"], dtype=np.float64)[None].repeat(len(folds), 0),
                               np.asarray(s["vaf_train"], dtype=np.float64))
        chosen: list[Choice] = choices(cv, s["threshold"], s["muscle_threshold"])
        written.append(figures.vaf_with_band(cv, chosen, out / "vaf.png", f"VAF ({s['method']})"))
    return [p for p in written if p is not None]
