"""Zero-shot evaluation on every core vs one: a SAC policy on the MyoSuite hand, evaluated on the
two unseen-object envs (myoHandReorientID-v0, myoHandReorientOOD-v0), 500 episodes each, once
with the envs stepping in this process (workers=1, the serial path) and once over all cores
(workers=2 on 2 cores: this process and one child), in one run. The results must be identical;
the wall times and their ratio are reported.

The policy is a randomly initialised SAC actor the size of the SAR study's (400 x 300, `sar-sac`
preset) written to a temporary run folder, unless --run names a trained one: what is measured is
the env stepping, and the policy acts in the parent process on both paths. Both paths start from
the same warm process (MyoSuite imported and its hand model built in it: one-time costs of a
process); the parallel time includes starting the child process, forked from this one (a process
running one thread; others start workers from the fork server, whose start is reported apart).
With --repeats, the paths alternate which runs first and the medians are reported.

Usage:  .venv/bin/python benchmarks/evaluate_parallel.py [--episodes 500] [--repeats 1] [--workers N] [--run RUN]
Prints one JSON object. Run it on an otherwise idle machine (it reports the load average).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

from provenance import Recorder  # benchmarks/provenance.py: the script's folder is on sys.path

from motorlab.envs import EnvConfig, make_env
from motorlab.evaluation.pool import _context as pool_context
from motorlab.evaluation.pool import available_cores
from motorlab.evaluation.zeroshot import transfer
from motorlab.policies import save_sb3_policy
from motorlab.runs import write_json

TRAINED_ON = "myoHandReorient8-v0"
UNSEEN = ["myoHandReorientID-v0", "myoHandReorientOOD-v0"]
TARGET_RATIO = 1.7  # issue 23: 2 x 500 zero-shot episodes >= 1.7x faster on a 2-core machine


def random_sac_run(folder: Path) -> Path:
    """A finished run folder holding an untrained SAC policy for the hand (as `motorlab train` writes it)."""
    from stable_baselines3 import SAC

    env = make_env(EnvConfig(id=TRAINED_ON), shaped=False)
    model = SAC("MlpPolicy", env, seed=0, device="cpu",
                policy_kwargs={"net_arch": {"pi": [400, 300], "qf": [400, 300]}})
    run = folder / "random-sac"
    run.mkdir(parents=True)
    save_sb3_policy(run, model, "sac")
    (run / "config.toml").write_text(f'algo = "sac"\n\n[env]\nid = "{TRAINED_ON}"\n')
    write_json(run / "summary.json", {})
    env.close()
    return run


def start_fork_server() -> None:
    """Start the fork server the pools' child processes come from (once a process, like imports)."""
    proc = pool_context().Process(target=os.getpid)  # returns once the server has imported its modules
    proc.start()
    proc.join()


def timed(run: Path, episodes: int, workers: int) -> tuple[float, dict]:
    start = time.perf_counter()
    t = transfer([run], UNSEEN, episodes=episodes, seed=0, workers=workers)
    return time.perf_counter() - start, t.results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=500, help="episodes per unseen env (500: the target's size)")
    parser.add_argument("--repeats", type=int, default=1, help="time both paths this many times; medians reported")
    parser.add_argument("--workers", type=int, default=available_cores(), help="processes of the parallel path")
    parser.add_argument("--run", type=Path, help="a trained hand run folder (default: an untrained SAC policy)")
    args = parser.parse_args()
    recorder = Recorder("evaluate_parallel")  # the git state and load, read as the run starts

    with tempfile.TemporaryDirectory() as tmp:
        run = args.run or random_sac_run(Path(tmp))
        for env_id in UNSEEN:  # MyoSuite's import and first model builds, out of both timings
            make_env(EnvConfig(id=env_id), shaped=False).close()
        start = time.perf_counter()
        if args.workers > 1:
            start_fork_server()
        server_s = time.perf_counter() - start
        load = os.getloadavg()
        serial, parallel, identical = [], [], True
        for k in range(args.repeats):
            order = (1, args.workers) if k % 2 == 0 else (args.workers, 1)
            times, results = {}, {}
            for workers in order:
                times[workers], results[workers] = timed(run, args.episodes, workers)
            serial.append(times[1])
            parallel.append(times[args.workers])
            identical = identical and results[1] == results[args.workers]
            print(f"repeat {k}: serial {times[1]:.1f} s, {args.workers} workers {times[args.workers]:.1f} s",
                  file=sys.stderr)
        one = results[1]

    s, p = statistics.median(serial), statistics.median(parallel)
    result = {
        "benchmark": "evaluate_parallel",
        "policy": str(args.run) if args.run else f"untrained SAC 400x300 for {TRAINED_ON}",
        "envs": UNSEEN,
        "episodes_per_env": args.episodes,
        "workers": args.workers,
        "serial_s": round(s, 2),
        "parallel_s": round(p, 2),
        "ratio": round(s / p, 3),
        "serial_runs_s": [round(x, 2) for x in serial],
        "parallel_runs_s": [round(x, 2) for x in parallel],
        "identical_results": identical,
        "fork_server_start_s": round(server_s, 2),
        "success_rate": {e: next(iter(one.values()))[e]["success_rate"] for e in UNSEEN},
        "target_ratio": TARGET_RATIO,
        "met": bool(identical and s / p >= TARGET_RATIO),
        "load_average_before": [round(x, 2) for x in load],
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "cores_available": available_cores(),
                    "processor": platform.processor() or platform.machine()},
    }
    recorder.record(result)


if __name__ == "__main__":
    main()
