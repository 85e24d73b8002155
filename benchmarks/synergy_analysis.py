"""Synergy analysis: recovery of known synergies, and the time of the field's analyses on a hand-sized recording.

    .venv/bin/python benchmarks/synergy_analysis.py [--samples 100000] [--surrogates 100] [--quick]

Part 1, recovery (motorlab.synergies.synthetic): activations from 4 known non-negative synergies over 12
muscles with noise (generator seeds --recovery-seeds, default 100-104, none used while the code was written,
which used seeds 0-3), and EMG made from them (carrier noise modulated by each activation, 2 kHz, 6 trials of
4 s). Per seed: NMF's matched cosine to the truth (Hungarian pairing), the N each criterion chooses on
5-fold cross-validated VAF (total >= 0.90, every muscle >= 0.75, the elbow), the shuffled null's 95th
percentile (100 surrogates); after `import-emg`'s envelope (band-pass 20-450 Hz, rectify, low-pass 6 Hz),
NMF's matched cosine to the truth. Targets: cosine >= 0.95 (activations) and >= 0.9 (EMG); N = 4 by each
criterion; the null's 95th percentile well below 0.95.

Part 2, time on the MyoSuite hand (myoHandReorient8-v0, 39 muscles): --samples steps of pink-noise (1/f)
random muscle commands, the muscles' activations (data.act) recorded (episodes of 100 steps). Timed on this
2-core machine:
  - cross-validated VAF, NMF, 5 folds of episodes, N = 1..20 (motorlab: folds and N in parallel, one
    process per core, scoring fits stopped at sklearn's tol 1e-3), against the same fits one after another
    in this process (the peer: a notebook's loop over sklearn's NMF), timed on one fold and scaled by 5;
  - the shuffled null: --surrogates surrogates, NMF at N = 10, each fit on all the samples (the default of
    `synergies compare`: the reference's own fit on shuffled data), in parallel, against the same fits one
    after another, timed on 4 surrogates and scaled;
  - what a smaller draw per surrogate does to the chance level (`--max-samples` 20,000 and 10,000, 20
    surrogates each): its p95 and time beside the full null's.
Target: <= 60 s each for motorlab's.
Output: one JSON object (benchmarks/results/synergy_analysis.json; --quick: -quick.json), with provenance.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from provenance import Recorder, seed_list  # benchmarks/ is the script's folder

HAND = "myoHandReorient8-v0"
TARGET_SECONDS = 60.0
EMG_RATE, EMG_TRIALS, EMG_SECONDS = 2000.0, 6, 4.0


def say(text: str) -> None:
    print(f"[synergy-analysis {time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def recovery(seed: int, surrogates: int) -> dict:
    """Part 1 on one generator seed."""
    from motorlab.synergies.analysis import choices, cross_validated_vaf
    from motorlab.synergies.similarity import chance, match
    from motorlab.synergies.synthetic import known_synergies
    from motorlab.synergies.vectors import fitted_vectors

    g = known_synergies(seed=seed, episodes=20)
    found = match(g.synergies, fitted_vectors(g.activations, "nmf", 4, seed))
    cv = cross_validated_vaf(g.activations, g.episode, "nmf", max_n=8, folds=5, seed=seed)
    null = chance(g.synergies, g.activations, "nmf", 4, surrogates, seed)
    return {"seed": seed, "matched_cosine": [round(v, 4) for v in found.similarity],
            "n_chosen": {c.criterion: c.n for c in choices(cv, 0.9, 0.75)},
            "held_out_vaf": [round(float(v), 4) for v in cv.mean], "null_pair_p95": round(null.p95, 4),
            "emg_matched_cosine": emg_recovery(seed)}


def emg_recovery(seed: int) -> list[float]:
    """EMG from 4 known synergies, imported (import-emg's defaults), NMF with N = 4: matched cosines."""
    import tempfile
    from pathlib import Path

    from motorlab.synergies.emg import import_emg
    from motorlab.synergies.similarity import match
    from motorlab.synergies.synthetic import known_synergies, synthetic_emg
    from motorlab.synergies.vectors import fitted_vectors

    length = int(EMG_SECONDS * EMG_RATE)
    g = known_synergies(seed=seed, episodes=EMG_TRIALS, length=length, noise=0.0)
    # the bursts are 1.5-5% of an episode (60-200 ms at this length): slow beside a 6 Hz envelope
    emg = synthetic_emg(g.activations, EMG_RATE, seed)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "emg.csv"
        header = ",".join(["trial", *g.names])
        rows = np.column_stack([g.episode, emg])
        np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt=["%d"] + ["%.6g"] * emg.shape[1])
        envelopes = import_emg(path, EMG_RATE)
    return [round(v, 4) for v in match(g.synergies, fitted_vectors(envelopes.activations, "nmf", 4, seed)).similarity]


def hand_activations(samples: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """`samples` steps of the hand under pink-noise muscle commands: data.act and each step's episode."""
    from motorlab.dynamics.collection import random_actions
    from motorlab.envs import EnvConfig, make_env
    from motorlab.synergy_runs.activations import muscle_activations

    env = make_env(EnvConfig(id=HAND), shaped=False)
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low, env.action_space.high
    acts, episodes, episode = [], [], 0
    while len(acts) < samples:
        env.reset(seed=seed + episode)
        for action in random_actions(rng, low, high, 1, 100, 1.0)[0]:
            _, _, terminated, truncated, _ = env.step(action)
            acts.append(muscle_activations(env))
            episodes.append(episode)
            if terminated or truncated or len(acts) >= samples:
                break
        episode += 1
    env.close()
    return np.asarray(acts, dtype=np.float64), np.asarray(episodes)


def timed(fn, *args, **kwargs) -> tuple[object, float]:
    t = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t


def serial_cv_one_fold(x: np.ndarray, episodes: np.ndarray, max_n: int) -> float:
    """The peer: one fold of the same fits, one after another in this process."""
    from sklearn.model_selection import GroupKFold

    from motorlab.synergies.analysis import _fit_and_score

    train, test = next(GroupKFold(n_splits=5).split(x, groups=episodes))
    t = time.perf_counter()
    for n in range(1, max_n + 1):
        _fit_and_score("nmf", n, x[train], x[test], 0)
    return time.perf_counter() - t


def serial_null(reference: np.ndarray, x: np.ndarray, n: int, surrogates: int) -> float:
    from motorlab.synergies.similarity import _surrogate

    t = time.perf_counter()
    for s in range(surrogates):
        _surrogate(reference, x, "nmf", n, s, False)
    return time.perf_counter() - t


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--samples", type=int, default=100_000, help="hand activation samples")
    p.add_argument("--surrogates", type=int, default=100)
    p.add_argument("--max-n", type=int, default=20)
    p.add_argument("--recovery-seeds", type=seed_list, default=seed_list("100-104"))
    p.add_argument("--quick", action="store_true", help="a smoke run: 5,000 samples, 10 surrogates, N up to 5, one seed")
    args = p.parse_args(argv)
    if args.quick:
        args.samples, args.surrogates, args.max_n, args.recovery_seeds = 5000, 10, 5, args.recovery_seeds[:1]
    recorder = Recorder("synergy_analysis")
    from motorlab.synergies.analysis import CV_TOL, cross_validated_vaf
    from motorlab.synergies.similarity import chance
    from motorlab.synergies.vectors import fitted_vectors

    say(f"recovery on generator seeds {args.recovery_seeds}")
    seeds = [recovery(s, args.surrogates) for s in args.recovery_seeds]
    for r in seeds:
        say(f"  seed {r['seed']}: cosine {min(r['matched_cosine'])}, N {r['n_chosen']}, null p95 {r['null_pair_p95']}, "
            f"EMG cosine {min(r['emg_matched_cosine'])}")
    say(f"{args.samples:,} hand activation samples ({HAND}, pink-noise commands)")
    (x, episodes), collect_s = timed(hand_activations, args.samples)
    cv, cv_s = timed(cross_validated_vaf, x, episodes, "nmf", args.max_n, 5)
    say(f"  cross-validated VAF (5 folds, N = 1..{args.max_n}): {cv_s:.1f} s")
    peer_cv_s = 5 * serial_cv_one_fold(x, episodes, args.max_n)
    say(f"  the same fits one after another (one fold x 5): {peer_cv_s:.1f} s")
    n_null = min(10, args.max_n)
    reference = fitted_vectors(x, "nmf", n_null, 0)
    null, null_s = timed(chance, reference, x, "nmf", n_null, args.surrogates, 0)
    say(f"  shuffled null ({args.surrogates} surrogates, N = {n_null}): {null_s:.1f} s")
    few = min(4, args.surrogates)
    peer_null_s = serial_null(reference, x, n_null, few) * args.surrogates / few
    say(f"  the same surrogates one after another ({few} x {args.surrogates / few:g}): {peer_null_s:.1f} s")
    smaller = {}
    for draw in (20_000, 10_000):
        if draw < x.shape[0]:
            fewer, fewer_s = timed(chance, reference, x, "nmf", n_null, min(20, args.surrogates), 0, draw)
            smaller[str(draw)] = {"surrogates": fewer.surrogates, "pair_p95": round(fewer.p95, 4),
                                  "seconds": round(fewer_s, 1)}
            say(f"  --max-samples {draw:,}: p95 {fewer.p95:.4f} ({fewer.surrogates} surrogates, {fewer_s:.1f} s)")
    cosines = [min(r["matched_cosine"]) for r in seeds]
    emg = [min(r["emg_matched_cosine"]) for r in seeds]
    result = {
        "recovery": {"per_seed": seeds, "min_matched_cosine": min(cosines), "min_emg_matched_cosine": min(emg),
                     "n_chosen_all_four": all(set(r["n_chosen"].values()) == {4} for r in seeds),
                     "max_null_pair_p95": max(r["null_pair_p95"] for r in seeds)},
        "hand": {"env": HAND, "samples": int(x.shape[0]), "muscles": int(x.shape[1]),
                 "episodes": int(np.unique(episodes).size), "collect_seconds": round(collect_s, 1),
                 "cross_validated_vaf": {"folds": 5, "max_n": args.max_n, "seconds": round(cv_s, 1), "nmf_tol": CV_TOL,
                                         "peer_serial_seconds": round(peer_cv_s, 1),
                                         "speedup": round(peer_cv_s / cv_s, 2),
                                         "held_out_vaf": [round(float(v), 4) for v in cv.mean],
                                         "held_out_vaf_fold_std": [round(float(v), 4) for v in cv.std]},
                 "null": {"surrogates": args.surrogates, "n": n_null, "samples_per_fit": null.samples,
                          "seconds": round(null_s, 1), "peer_serial_seconds": round(peer_null_s, 1),
                          "speedup": round(peer_null_s / null_s, 2), "pair_p95": round(null.p95, 4),
                          "smaller_draws": smaller}},
        "workers": os.cpu_count(),
        "targets": {"recovery_cosine": {"target": ">= 0.95", "value": min(cosines), "met": min(cosines) >= 0.95},
                    "emg_cosine": {"target": ">= 0.9", "value": min(emg), "met": min(emg) >= 0.9},
                    "n_by_each_criterion": {"target": "N = 4 by each criterion on every seed",
                                            "met": all(set(r["n_chosen"].values()) == {4} for r in seeds)},
                    "cv_seconds": {"target": f"<= {TARGET_SECONDS:g} s", "value": round(cv_s, 1),
                                   "met": cv_s <= TARGET_SECONDS},
                    "null_seconds": {"target": f"<= {TARGET_SECONDS:g} s", "value": round(null_s, 1),
                                     "met": null_s <= TARGET_SECONDS}},
    }
    recorder.record(result, file="synergy_analysis" + ("-quick" if args.quick else ""))


if __name__ == "__main__":  # joblib's worker processes re-import this file
    main()
