"""Per-step cost of the SAR action mapping: motorlab's affine decode vs scikit-learn's chain.

Uses the SAR published with MyoSuite for manipulation (39 muscles, 20 synergies),
imported with trust into a temporary folder. Times (timeit, median of several
runs, microseconds):

- motorlab ``sar.decode(z)`` for one step, z of shape (20,)
- motorlab ``sar.decode(Z)`` for a batch of 1024, per sample
- the blended action of one step, ``phi * decode(z) + (1 - phi) * raw`` with phi = 0.66
- scikit-learn ``pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z[None])))[0]``
  for one step (what MyoSuite's SAR wrapper does)

BLAS is limited to one thread for both sides.

Usage:  .venv/bin/python benchmarks/sar_decode.py [--data DIR] [--runs 7]
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import timeit
import warnings
from pathlib import Path

import numpy as np
from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

from motorlab.synergies.sklearn_import import import_sklearn

DATA = Path(__file__).resolve().parents[2] / "shared/data/myosuite_sar_pretrained/manipulation"
TARGET_US_PER_STEP = 5.0
PHI = 0.66
BATCH = 1024


def median_us(stmt, number: int, runs: int, per: int = 1) -> float:
    """Median over `runs` of the mean time of one call (divided by `per`), in microseconds."""
    timer = timeit.Timer(stmt)
    timer.timeit(number=max(1, number // 10))  # warm-up
    return statistics.median(t / number / per * 1e6 for t in timer.repeat(repeat=runs, number=number))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA, help="folder with pca.pkl, ica.pkl, normalizer.pkl")
    parser.add_argument("--runs", type=int, default=7, help="timeit repeats; the median is reported")
    args = parser.parse_args()
    recorder = Recorder("sar_decode")  # the git state and load, read as the run starts

    import joblib
    import sklearn
    from threadpoolctl import threadpool_limits

    # One BLAS thread: an env step is single-threaded work, and OpenBLAS threads on a busy
    # machine make batch timings swing 10x. Both sides get the same setting.
    threadpool_limits(limits=1, user_api="blas")

    with tempfile.TemporaryDirectory() as tmp:
        sar = import_sklearn(args.data, trust=True, out=Path(tmp) / "sar.npz")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the pickles come from an older sklearn
        pca, ica, scaler = (joblib.load(args.data / f) for f in ("pca.pkl", "ica.pkl", "normalizer.pkl"))

    rng = np.random.default_rng(0)
    z = rng.uniform(-1, 1, sar.n_synergies)
    zb = rng.uniform(-1, 1, (BATCH, sar.n_synergies))
    raw = rng.uniform(-1, 1, sar.n_muscles)
    decode = sar.decode

    def sk_step():
        return pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(z[None])))[0]

    def blended():
        return PHI * decode(z) + (1 - PHI) * raw

    # The real per-step action mapping: SynergyActionWrapper.action on an env with M muscle actions.
    import gymnasium as gym

    from motorlab.synergies import SynergyActionWrapper

    class Muscles(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (sar.n_muscles,), np.float32)

    wrapped = {phi: SynergyActionWrapper(Muscles(), sar, phi) for phi in (PHI, 1.0)}
    actions = {phi: w.action_space.sample() for phi, w in wrapped.items()}
    wrapper_us = {phi: median_us(lambda w=w, a=actions[phi]: w.action(a), 20000, args.runs) for phi, w in wrapped.items()}

    max_err = float(np.max(np.abs(decode(z) - sk_step())))
    ours = median_us(lambda: decode(z), 20000, args.runs)
    batched = median_us(lambda: decode(zb), 500, args.runs, per=BATCH)
    blend = median_us(blended, 20000, args.runs)
    theirs = median_us(sk_step, 1000, args.runs)
    sk_batched = median_us(
        lambda: pca.inverse_transform(ica.inverse_transform(scaler.inverse_transform(zb))), 100, args.runs, per=BATCH)

    result = {
        "benchmark": "sar_decode",
        "sar": f"myosuite manipulation ({sar.n_synergies} synergies -> {sar.n_muscles} muscles)",
        "motorlab_us_per_step": round(ours, 3),
        "motorlab_batched_us_per_sample": round(batched, 4),
        "motorlab_blend_phi_0.66_us_per_step": round(blend, 3),
        "wrapper_action_phi_0.66_us_per_step": round(wrapper_us[PHI], 3),
        "wrapper_action_phi_1_us_per_step": round(wrapper_us[1.0], 3),
        "sklearn_chain_us_per_step": round(theirs, 3),
        "sklearn_chain_batched_us_per_sample": round(sk_batched, 4),
        "ratio_sklearn_over_motorlab": round(theirs / ours, 2),
        "ratio_sklearn_over_wrapper_phi_0.66": round(theirs / wrapper_us[PHI], 2),
        "max_abs_diff_vs_sklearn": max_err,
        "target_us_per_step": TARGET_US_PER_STEP,
        # the target is the whole per-step mapping, so the blended wrapper step must meet it
        "met": bool(max(ours, wrapper_us[PHI], wrapper_us[1.0]) <= TARGET_US_PER_STEP),
        "timing": f"timeit, median of {args.runs} runs, 1 BLAS thread",
        "machine": {"python": platform.python_version(), "numpy": np.__version__, "sklearn": sklearn.__version__,
                    "cpus": os.cpu_count(), "processor": platform.processor() or platform.machine()},
    }
    recorder.record(result)


if __name__ == "__main__":
    main()
