"""Which learner gets furthest in an hour of this machine: success at equal WALL time on MyoSuite tasks.

    .venv/bin/python benchmarks/learner_per_hour.py screen  [--minutes 10] [--keep DIR] [--resume] [--stop-after 55]
    .venv/bin/python benchmarks/learner_per_hour.py confirm [--minutes 10] [--keep DIR] [--resume] [--stop-after 55]

Why: the SAR studies' reference SAC (one update of [400, 300] networks per env step) is FLOP-bound
at ~30 updates/s a core, so on a laptop it sees few env steps; cheaper learners see many more but
learn less from each. rl-zoo3 tunes for env steps and MyoSuite's baselines assume a cluster: this
measures learning per wall-clock minute, the budget a small machine's user has.

Protocol
  Tasks: myoFingerPoseRandom-v0 (a finger, 5 muscles) and myoHandPoseRandom-v0 (the hand, all 39
  muscles). Success: MyoSuite's "solved" at any step of a deterministic episode.
  Each run: `motorlab train TASK --preset CONTENDER --minutes M --eval-every-minutes M/10` in its own
  process, pinned to ONE core (taskset; its env processes too), one torch thread, two runs at a time
  (one per core). `--minutes` counts training only: evaluations and checkpoints are not charged, so
  a learner evaluated more often pays nothing for it. The env-step budget is set far beyond what M
  minutes reach (50M), so the run ends on the clock; the presets' linear learning-rate schedules
  (over that budget) are therefore near constant here, as they are in the first minutes of a study.
  Every M/10 minutes of training the policy plays --episodes deterministic episodes (reset seeds fixed
  by the run's seed); the last evaluation is the saved policy's, on the same episodes.
  Contenders (motorlab presets, motorlab/algos/):
    sar-sac          the reference: SAR's SAC, one gradient step per env step, [400, 300] networks
    sar-sac-half     ... one gradient step per 2 env steps; -quarter 4; -eighth 8
    sar-sac-256      ... [256, 256] networks
    sar-sac-fast     4 env processes, 4 gradient steps per 100 env steps (the SAR recipes' learner so far)
    sar-ppo          PPO, 4 env processes, [256, 256]
    sar-crossq       CrossQ, one update per env step, [256, 256] actor, [512, 512] critics
  (TQC is not screened: its update costs ~2x SAC's at equal networks, CrossQ is the cheaper of the two.)

Phases (benchmarks/provenance.py's Harness: development and headline seeds apart by construction)
  screen   every contender on development seed 0 per task: writes one line to
           benchmarks/devlog/learner_per_hour.jsonl (never a result file), with the best two per task.
  confirm  the screen's best two per task (the latest screen line of the same minutes and tasks;
           --contenders overrides) and the reference, on headline seeds 100-102: writes
           benchmarks/results/learner_per_hour.json (from committed code: run it from a git worktree).
  Split over invocations: --keep DIR keeps every run folder (DIR/TASK/CONTENDER/seedS); --resume reads
  finished ones back and starts the rest; --stop-after MIN starts no run that would end after MIN
  minutes of this invocation (the JSON is written once every run is there). A run killed midway
  starts over.

Measured, per task and contender: success and return at each evaluation against training minutes and
against env steps; env steps per second; the final success per seed, across seeds (the seeds' range at
3, a bootstrap interval from 5) and pooled over episodes (Wilson); the mean curve over seeds on the
grid of evaluation marks; the Pareto front over (training minutes, mean success): the points no other
contender beats at equal or less time; the winner (highest final mean success, then return) and its
lead over the runner-up and the reference, with P(winner > other) over seeds.

Time: screen 8 contenders x 2 tasks x (M + ~1.5 min of start-up and evaluation) / 2 cores: ~92 min at
M = 10 (two invocations); confirm (3 contenders x 2 tasks x 3 seeds) ~104 min (two invocations).
--quick: M = 0.5, 2 contenders, --episodes 4: a smoke run of a few minutes, results/learner_per_hour-quick.json
or its own devlog.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from provenance import Harness, SeedPlan, devlog_entries, seed_list  # benchmarks/ is the script's folder

TASKS = ("myoFingerPoseRandom-v0", "myoHandPoseRandom-v0")
REFERENCE = "sar-sac"
CONTENDERS = ("sar-sac", "sar-sac-half", "sar-sac-quarter", "sar-sac-eighth", "sar-sac-256", "sar-sac-fast",
              "sar-ppo", "sar-crossq")
SCREEN_SEEDS, CONFIRM_SEEDS = [0], [100, 101, 102]
STEP_BUDGET = 50_000_000  # never reached: the clock ends every run
EVALUATIONS = 10  # per run, one every minutes / 10 of training
OVERHEAD_MINUTES = 1.5  # start-up, evaluations and the final evaluation, per run (for --stop-after)
QUICK = {"minutes": 0.5, "contenders": ("sar-sac", "sar-ppo"), "episodes": 4}
SEEDS = SeedPlan(development=range(0, 100), headline=range(100, 1000))


@dataclass(frozen=True)
class Point:
    """One evaluation of a run."""

    minutes: float  # of training (evaluations not counted)
    steps: int
    success: float
    ret: float


def read_curve(run_dir: Path) -> list[Point]:
    """The evaluations of a run (metrics.csv's evaluation rows), in order."""
    import csv

    with open(run_dir / "metrics.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r.get("eval_return_mean")]
    return [Point(float(r["train_seconds"]) / 60, int(float(r["timesteps"])), float(r["eval_success_rate"]),
                  float(r["eval_return_mean"])) for r in rows]


def value_at(curve: list[Point], minutes: float, what: str = "success") -> float | None:
    """A run's evaluation `what` at `minutes` of training: its last evaluation at or before then (None before the first)."""
    before = [p for p in curve if p.minutes <= minutes + 1e-9]
    return getattr(before[-1], what) if before else None


def mean_curve(curves: list[list[Point]], marks: list[float], what: str = "success") -> list[float | None]:
    """The mean over seeds at each mark (None where a seed has no evaluation yet)."""
    out: list[float | None] = []
    for m in marks:
        values = [value_at(c, m, what) for c in curves]
        out.append(None if any(v is None for v in values) else sum(values) / len(values))
    return out


def pareto_front(means: dict[str, list[float | None]], marks: list[float]) -> list[dict]:
    """The (minutes, mean success) points no other point beats: one with less or equal time and at least
    as much success (one strictly). Ties on both keep every contender that has the point."""
    points = [(m, s, name) for name, curve in means.items() for m, s in zip(marks, curve) if s is not None]
    front = [(m, s, name) for m, s, name in points
             if not any(m2 <= m and s2 >= s and (m2 < m or s2 > s) for m2, s2, _ in points)]
    return [{"minutes": round(m, 4), "success": round(s, 4), "contender": name} for m, s, name in sorted(front)]


def ranking(final: dict[str, tuple[list[float], list[float]]]) -> list[str]:
    """Contenders by mean final success over seeds, then mean final return (both higher first), then name."""
    def key(name: str) -> tuple[float, float, str]:
        success, returns = final[name]
        return (-sum(success) / len(success), -sum(returns) / len(returns), name)

    return sorted(final, key=key)


def task_result(runs: dict[str, dict[int, dict]], minutes: float) -> dict:
    """One task: runs[contender][seed] = {"curve": [Point], "summary": summary.json}."""
    from motorlab.intervals import across_seeds, p_better, pooled_rate

    marks = [round(minutes * (i + 1) / EVALUATIONS, 6) for i in range(EVALUATIONS)]
    per: dict[str, dict] = {}
    final: dict[str, tuple[list[float], list[float]]] = {}
    means: dict[str, list[float | None]] = {}
    for name, by_seed in runs.items():
        seeds = sorted(by_seed)
        summaries = [by_seed[s]["summary"] for s in seeds]
        curves = [by_seed[s]["curve"] for s in seeds]
        success = [float(s["eval_success_rate"]) for s in summaries]
        returns = [float(s["eval_return_mean"]) for s in summaries]
        episodes = [int(s["eval_episodes"]) for s in summaries]
        final[name] = (success, returns)
        means[name] = mean_curve(curves, marks)
        per[name] = {
            "seeds": seeds, "success_per_seed": success, "return_per_seed": [round(r, 3) for r in returns],
            "success": across_seeds(success).to_json(), "return": across_seeds(returns).to_json(),
            "success_pooled": pooled_rate([round(r * n) for r, n in zip(success, episodes)], episodes).to_json(),
            "env_steps_per_seed": [int(s["timesteps"]) for s in summaries],
            "env_steps_per_second": [round(int(s["timesteps"]) / float(s["train_seconds"]), 1) for s in summaries],
            "train_minutes_per_seed": [round(float(s["train_seconds"]) / 60, 3) for s in summaries],
            "stopped_by": sorted({s["stopped_by"] for s in summaries}),
            "success_curve_mean": means[name],
            "return_curve_mean": mean_curve(curves, marks, "ret"),
            "curves": {str(s): [[round(p.minutes, 4), p.steps, p.success, round(p.ret, 3)] for p in c]
                       for s, c in zip(seeds, curves)},
        }
    order = ranking(final)
    winner = order[0]
    leads = {}
    for other in order[1:]:
        leads[other] = {"success_difference": round(sum(final[winner][0]) / len(final[winner][0])
                                                    - sum(final[other][0]) / len(final[other][0]), 4),
                        "p_winner_better_success": p_better(final[winner][0], final[other][0]).to_json()}
    return {"marks_minutes": marks, "ranking": order, "winner": winner, "winner_leads": leads,
            "pareto_front": pareto_front(means, marks),
            "on_the_front": sorted({p["contender"] for p in pareto_front(means, marks)}), "contenders": per}


# ------------------------------------------------------------------------------------------------ running

def run_folder(root: Path, task: str, contender: str, seed: int) -> Path:
    return root / task / contender / f"seed{seed}"


def train_command(task: str, contender: str, seed: int, minutes: float, episodes: int, out: Path) -> list[str]:
    return [sys.executable, "-m", "motorlab", "train", task, "--preset", contender, "--seed", str(seed),
            "--timesteps", str(STEP_BUDGET), "--minutes", str(minutes),
            "--eval-every-minutes", str(minutes / EVALUATIONS), "--solve-episodes", str(episodes),
            "--torch-threads", "1", "--checkpoint-every", "0", "--no-progress", "--out", str(out)]


def run_all(jobs: list[tuple[str, str, int]], args: argparse.Namespace, root: Path) -> list[tuple[str, str, int]]:
    """Train every job not finished under root, two at a time, each pinned to its own core; returns the
    jobs left undone (--stop-after)."""
    started = time.monotonic()
    cores: queue.Queue[int] = queue.Queue()
    for core in sorted(os.sched_getaffinity(0))[:args.jobs]:
        cores.put(core)
    left: list[tuple[str, str, int]] = []

    def one(job: tuple[str, str, int]) -> None:
        task, contender, seed = job
        out = run_folder(root, *job)
        if (out / "summary.json").is_file():
            return
        if args.stop_after and (time.monotonic() - started) / 60 + args.minutes + OVERHEAD_MINUTES > args.stop_after:
            left.append(job)
            return
        core = cores.get()
        try:
            import shutil

            shutil.rmtree(out, ignore_errors=True)  # a run killed midway starts over
            out.parent.mkdir(parents=True, exist_ok=True)
            t = time.perf_counter()
            cmd = ["taskset", "-c", str(core), *train_command(task, contender, seed, args.minutes, args.episodes, out)]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise SystemExit(f"{task} {contender} seed {seed} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
            s = json.loads((out / "summary.json").read_text())
            say(f"{task} {contender} seed {seed} (core {core}): success {s['eval_success_rate']:.2f}, return "
                f"{s['eval_return_mean']:.2f}, {s['timesteps']:,} env steps in {s['train_seconds'] / 60:.1f} min "
                f"of training ({time.perf_counter() - t:.0f} s in all)")
        finally:
            cores.put(core)

    with ThreadPoolExecutor(args.jobs) as pool:
        list(pool.map(one, jobs))
    return left


def say(text: str) -> None:
    print(f"[learner-per-hour {time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def screened_best(minutes: float, tasks: list[str], log: str) -> dict[str, list[str]]:
    """The best two per task of the latest screen with these minutes and tasks (the devlog)."""
    for entry in reversed(devlog_entries(log)):
        s = entry.get("settings", {})
        if s.get("phase") == "screen" and s.get("minutes") == minutes and s.get("tasks") == tasks:
            return {t: entry["result"]["tasks"][t]["ranking"][:2] for t in tasks}
    raise SystemExit(f"no screen of {tasks} at {minutes} min in benchmarks/devlog/{log}.jsonl: run the screen "
                     "first (or give --contenders)")


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("phase", choices=("screen", "confirm"))
    p.add_argument("--minutes", type=float, default=None, help="minutes of training per run (one core); default 10")
    p.add_argument("--tasks", default=",".join(TASKS), type=lambda t: [x for x in t.split(",") if x])
    p.add_argument("--contenders", default=None, type=lambda t: [x for x in t.split(",") if x],
                   help="screen: all of them by default; confirm: the screen's best two per task, and the reference")
    p.add_argument("--seeds", type=seed_list, default=None, help="screen: 0; confirm: 100-102")
    p.add_argument("--episodes", type=int, default=None, help="deterministic episodes per evaluation; default 30")
    p.add_argument("--jobs", type=int, default=2, help="runs at a time, each pinned to its own core")
    p.add_argument("--keep", type=Path, default=None, help="keep run folders here (needed to split with --resume)")
    p.add_argument("--resume", action="store_true", help="with --keep: read finished runs back, start the rest")
    p.add_argument("--stop-after", type=float, default=None, metavar="MIN",
                   help="start no run that would end after MIN minutes of this invocation")
    p.add_argument("--quick", action="store_true", help="a smoke run: " + json.dumps(QUICK))
    args = p.parse_args(argv)
    defaults = QUICK if args.quick else {"minutes": 10.0, "episodes": 30, "contenders": None}
    for key, value in defaults.items():  # what is given wins over --quick's
        if getattr(args, key) is None:
            setattr(args, key, list(value) if isinstance(value, tuple) else value)
    if args.seeds is None:
        args.seeds = SCREEN_SEEDS if args.phase == "screen" else CONFIRM_SEEDS
    if args.resume and not args.keep:
        p.error("--resume reads the run folders of --keep DIR: give --keep")
    unknown = [c for c in args.contenders or [] if c not in CONTENDERS]
    if unknown:
        p.error(f"unknown contender(s) {unknown}; contenders: {', '.join(CONTENDERS)}")
    SEEDS.mode(args.seeds)  # development or headline, never a mix
    return args


def main(argv: list[str] | None = None) -> None:
    import tempfile

    args = parse(argv)
    log = "learner_per_hour" + ("-quick" if args.quick else "")
    if args.phase == "screen":
        chosen = {t: list(args.contenders or CONTENDERS) for t in args.tasks}
    elif args.contenders:
        chosen = {t: list(dict.fromkeys([REFERENCE, *args.contenders])) for t in args.tasks}
    else:
        chosen = {t: list(dict.fromkeys([REFERENCE, *best])) for t, best in screened_best(args.minutes, args.tasks,
                                                                                         log).items()}
    settings = {"phase": args.phase, "minutes": args.minutes, "tasks": args.tasks, "contenders": chosen,
                "episodes": args.episodes, "evaluations": EVALUATIONS, "jobs": args.jobs, "step_budget": STEP_BUDGET}
    run = Harness("learner_per_hour", seeds=SEEDS).start(args.seeds, settings, log=log)
    jobs = [(t, c, s) for s in args.seeds for t in args.tasks for c in chosen[t]]
    say(f"{args.phase} ({run.mode}): {len(jobs)} runs of {args.minutes} min, {args.jobs} at a time; seeds {args.seeds}")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        if args.keep and not args.resume and any(run_folder(root, *j).exists() for j in jobs):
            raise SystemExit(f"{root} already holds runs of these jobs: pass --resume, or choose another --keep")
        left = run_all(jobs, args, root)
        if left:
            say(f"{len(left)} run(s) left for another invocation (--stop-after): run again with --keep {root} --resume")
            return
        runs = {t: {c: {s: {"curve": read_curve(run_folder(root, t, c, s)),
                            "summary": json.loads((run_folder(root, t, c, s) / "summary.json").read_text())}
                        for s in args.seeds} for c in chosen[t]} for t in args.tasks}
    result = {"protocol": {"one_core_per_run": True, "torch_threads": 1, "minutes_of_training": args.minutes,
                           "evaluation_episodes": args.episodes, "evaluations_per_run": EVALUATIONS,
                           "success": 'MyoSuite\'s "solved" at any step of a deterministic episode'},
              "seeds": args.seeds, "tasks": {t: task_result(runs[t], args.minutes) for t in args.tasks}}
    result["best_two"] = {t: r["ranking"][:2] for t, r in result["tasks"].items()}
    run.finish(result, file="learner_per_hour" + ("-quick" if args.quick else ""))


if __name__ == "__main__":  # the PPO and sar-sac-fast runs start env subprocesses
    main()
