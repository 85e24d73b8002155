"""The tuned SAC of benchmarks/mbrl.py: an Optuna search on DEVELOPMENT seeds, so the loop meets a
baseline tuned with equal effort rather than SB3's defaults.

    .venv/bin/python benchmarks/sac_tune.py ENV [--trials 8] [--seeds 0,1] [--steps 10000]

rl-zoo3 has no SAC settings for these envs (its sac.yml tunes the MuJoCo locomotion tasks and the
PyBullet ones; Reacher-v5, Pusher-v5, InvertedPendulum-v5, the bundled cart-pole and the arm are
not there), so the issue's fallback applies: a search of equal effort, on development seeds.

Equal effort, or more: --trials defaults to twice the configurations the loop's development log
holds for the env (benchmarks/devlog/mbrl-ENV.jsonl; Pusher's six, Reacher's two), and at least 6. Each trial trains SAC on every --seeds seed (2 at a
time, one torch thread each) for --steps env steps, evaluated as the benchmark does (every loop round
of env steps, 10 episodes on the seed's own evaluation reset seeds, deterministic policy), and scores
the mean over seeds of the mean return over its evaluations: the area under the learning curve,
which rewards learning early, what steps-to-threshold measures.

The search space is rl-zoo3's `sample_sac_params` (rl_zoo3/hyperparams_opt.py), trimmed to what
matters within a 30k-step cap: gamma, learning rate, batch size, learning_starts, train_freq (=
gradient_steps), tau and the network size; ent_coef stays auto.

Storage: an Optuna journal (a text file, benchmarks/devlog/sac_tune-ENV.journal), so an interrupted
search resumes where it stopped and its history is readable; every trial is also one line of the
development log, benchmarks/devlog/sac_tune-ENV.jsonl (provenance.Harness). The best trial's params go
to benchmarks/sac_tuned.json under the env id, which mbrl.py's tuned variant reads.

Seeds: development only (0-99); a headline seed is refused. Time on this 2-core machine: a trial is
~1-2 min on Reacher at 5k steps and 2 seeds on an idle machine (SAC ~10-13 s of wall per 1k env
steps), several times that on a loaded one.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import mbrl  # noqa: E402
from provenance import (  # noqa: E402
    DEVLOG,
    SCIENCE_SEEDS,
    Harness,
    configurations_tried,
    devlog_entries,
    git_state,
    seed_list,
    write_result,
)

TUNED = mbrl.TUNED


def sample(trial) -> dict:
    """SB3 SAC keyword arguments (rl-zoo3's sample_sac_params, trimmed)."""
    train_freq = trial.suggest_categorical("train_freq", [1, 4, 8])
    net = trial.suggest_categorical("net_arch", ["small", "medium", "big"])
    return {"gamma": trial.suggest_categorical("gamma", [0.95, 0.98, 0.99]),
            "learning_rate": trial.suggest_float("learning_rate", 1e-4, 3e-3, log=True),
            "batch_size": trial.suggest_categorical("batch_size", [64, 128, 256, 512]),
            "learning_starts": trial.suggest_categorical("learning_starts", [100, 1000, 3000]),
            "train_freq": train_freq, "gradient_steps": train_freq,
            "tau": trial.suggest_categorical("tau", [0.005, 0.01, 0.02]),
            "policy_kwargs": {"net_arch": {"small": [64, 64], "medium": [256, 256], "big": [400, 300]}[net]}}


def score(runs: list[dict]) -> float:
    """The mean over seeds of each run's mean evaluation return (the area under its learning curve)."""
    return sum(sum(p["return_mean"] for p in r["curve"]) / len(r["curve"]) for r in runs) / len(runs)


def parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("env", choices=list(mbrl.ENVS))
    parser.add_argument("--trials", type=int, default=None,
                        help="trials in all, a resumed search counting its earlier ones (default: twice the loop's "
                             "configurations in its development log, at least 6)")
    parser.add_argument("--seeds", type=seed_list, default=[0, 1], help="development seeds, e.g. 0,1")
    parser.add_argument("--steps", type=int, default=5_000, help="env steps per trial and seed")
    parser.add_argument("--jobs", type=int, default=2, help="SAC processes at once")
    parser.add_argument("--sampler-seed", type=int, default=0)
    args = parser.parse_args(argv)
    if SCIENCE_SEEDS.mode(args.seeds) != "development":
        parser.error("the search runs on development seeds only")
    if args.trials is None:
        args.trials = max(6, 2 * configurations_tried(devlog_entries(f"mbrl-{args.env}")))
    return args


DEFAULT_BUDGET = (5_000, (0, 1))  # --steps, --seeds


def study_name(env: str, steps: int, seeds: list[int]) -> str:
    """The Optuna study a search resumes: one per budget, so trials at other --steps or --seeds never
    share a study (their scores are not comparable). The default budget keeps the name the first
    searches were recorded under."""
    if (steps, tuple(seeds)) == DEFAULT_BUDGET:
        return f"sac-{env}"
    return f"sac-{env}-{steps}steps-seeds{'-'.join(map(str, seeds))}"


def main(argv: list[str] | None = None) -> dict:
    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    args = parse(argv)
    env = mbrl.ENVS[args.env]
    every = mbrl.eval_interval(args.env, env["budget"], {})
    DEVLOG.mkdir(parents=True, exist_ok=True)
    storage = JournalStorage(JournalFileBackend(str(DEVLOG / f"sac_tune-{args.env}.journal")))
    study = optuna.create_study(study_name=study_name(args.env, args.steps, args.seeds), storage=storage,
                                direction="maximize",
                                sampler=optuna.samplers.TPESampler(seed=args.sampler_seed), load_if_exists=True)
    harness = Harness("sac_tune")
    started = git_state()
    while len([t for t in study.trials if t.state.is_finished()]) < args.trials:
        trial = study.ask()
        params = sample(trial)
        settings = {"env_id": env["id"], "steps": args.steps, "eval_every": every, "params": params}
        run = harness.start(args.seeds, settings, log=f"sac_tune-{args.env}")
        t = time.perf_counter()
        jobs = [(env["id"], s, args.steps, every, mbrl.eval_seeds(s, mbrl.EVAL_EPISODES), None, "tuned", params)
                for s in args.seeds]
        runs = mbrl.in_processes(mbrl.run_sac, jobs, args.jobs,
                                 lambda r, n=trial.number: f"trial {n} seed {r['seed']}: final "
                                                           f"{r['curve'][-1]['return_mean']:.2f}")
        value = score(runs)
        study.tell(trial, value)
        run.finish({"trial": trial.number, "score_auc_mean_return": value, "wall_seconds": round(time.perf_counter() - t),
                    "final_return_mean": [r["curve"][-1]["return_mean"] for r in runs]})
    best = study.best_trial
    table = json.loads(TUNED.read_text()) if TUNED.is_file() else {}
    finished = [t for t in study.trials if t.state.is_finished()]
    table[env["id"]] = {"params": sample(optuna.trial.FixedTrial(best.params)), "score_auc_mean_return": best.value,
                        "trials": len(finished), "seeds": args.seeds, "steps": args.steps, "eval_every": every,
                        "search": f"benchmarks/devlog/sac_tune-{args.env}.journal",
                        "devlog": f"benchmarks/devlog/sac_tune-{args.env}.jsonl",
                        "commit": started.get("commit"), "date": time.strftime("%Y-%m-%d"),
                        "argv": sys.argv[1:] if argv is None else argv}
    write_result(table, TUNED)
    print(json.dumps(table[env["id"]], indent=2))
    return table[env["id"]]


if __name__ == "__main__":
    main()
