"""Muscle synergies from Python (`motorlab synergies ...`): collect, VAF, fit, import, export.

```python
play = motorlab.train("myoHandReorient8-v0", preset="sar-sac-fast", timesteps=50_000)
acts = motorlab.api.synergies.collect(play, episodes=200)
motorlab.api.synergies.vaf(acts)                      # how many synergies explain 80%?
sar = motorlab.api.synergies.fit(acts, n_synergies=20)
motorlab.train("myoHandReorient100-v0", sar=sar, phi=0.5)
```
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab.api import running
from motorlab.api.checks import api_function
from motorlab.api.views import Result
from motorlab.kinds.synergies import COLLECT, FIT, VAF

__all__ = ["collect", "vaf", "fit", "import_sklearn", "export_sklearn", "load_sar"]


@api_function
def collect(run: str | Path | Result, episodes: int | None = None, *, out: str | Path | None = None,
            progress: bool = True, **settings: Any) -> Result:
    """Record muscle activations of a trained policy's good episodes (`motorlab synergies collect`).

    Args:
        run: the play policy: a training `Run` or its folder.
        episodes: episodes to keep (default 100): rollouts go on until this many score at or
            above the threshold that the first `preview` episodes set.
        **settings: percentile (the threshold's percentile of the preview's returns, default 80), signal ("auto", "act",
            "ctrl", "action"), deterministic, preview, max_episodes, seed, workers.

    Returns:
        Its folder, with activations.npz (steps x muscles).
    """
    return running.run_kind(COLLECT, out, progress, run=run, episodes=episodes, **settings)


@api_function
def vaf(activations: str | Path | Result, *, threshold: float | None = None, out: str | Path | None = None,
        **settings: Any) -> Result:
    """Variance accounted for by 1..N synergies (`motorlab synergies vaf`): vaf.png and the
    smallest N that reaches `threshold` (default 0.8) in `["n_for_threshold"]`.

    Args:
        activations: a `collect` result, its folder or activations.npz.
        **settings: method ("pca", "nmf"), max_n.
    """
    return running.run_kind(VAF, out, activations=activations, threshold=threshold, **settings)


@api_function
def fit(activations: str | Path | Result, n_synergies: int | None = None, *, out: str | Path | None = None,
        **settings: Any) -> Result:
    """Fit a Synergistic Action Representation (`motorlab synergies fit`): sar.npz, no pickle.

    Args:
        activations: a `collect` result, its folder or activations.npz.
        n_synergies: synergies to keep (or vaf=0.9: as many as reach that VAF).
        **settings: method ("pca-ica", "pca", "nmf"), vaf, seed.

    Returns:
        Its folder; `load_sar(result)` gives the SAR, and `train(..., sar=result)` trains in its space.
    """
    return running.run_kind(FIT, out, activations=activations, n_synergies=n_synergies, **settings)


@api_function
def import_sklearn(folder: str | Path, out: str | Path, *, trust: bool = False) -> Path:
    """Convert a published scikit-learn SAR (MyoSuite's joblib pickles) to sar.npz, checked
    against scikit-learn's own inverse chain (`motorlab synergies import-sklearn`).

    Args:
        trust: allow unpickling the files; they can run code, so give it only for files you trust.

    Returns:
        The sar.npz written.

    Raises:
        MotorlabError: without `trust`, or files that are not a SAR.
    """
    from motorlab.synergies.sklearn_import import import_sklearn as convert

    convert(Path(folder), trust=trust, out=Path(out))
    return Path(out)


@api_function
def export_sklearn(sar: str | Path | Result, out: str | Path) -> Path:
    """Write a SAR as a MyoSuite 3.0 SynergyModel folder (`motorlab synergies export-sklearn`)."""
    from motorlab.synergies.sklearn_export import export_sklearn as write

    write(Path(running.path_of(sar)), Path(out))
    return Path(out)


@api_function
def load_sar(sar: str | Path | Result):
    """The SAR of a sar.npz or a `fit` result: `.decode(z)` maps synergies to muscle activations."""
    from motorlab.synergies.sar import load_sar as read

    return read(Path(running.path_of(sar)))
