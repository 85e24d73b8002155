"""`motorlab mbrl` against SB3 SAC: env steps to a fixed threshold, one env per invocation.

    .venv/bin/python benchmarks/mbrl.py ENV [--seeds 100-104] [--sac default,tuned] [--keep DIR]
                                           [--sac-from DIR/runs.json] [--sac-full] [--quick]

ENV is one of (threshold, the loop's budget of env steps, the target: loop seeds reaching the
threshold within that budget):

  pendulum  InvertedPendulum-v5          1000 on ALL 10 evaluation episodes (their min)     2,000   >= 4 of 5
  reacher   Reacher-v5                   mean return >= -5.0                                3,000   >= 4 of 5
  cartpole  CartpoleSwingup-v0 (bundled) mean return >= 170 (of 200)                        3,000   >= 4 of 5
  pusher    Pusher-v5                    SB3-default SAC's mean over its seeds (IQM from 4)  6,000   >= 3 of 5
                                         of its final mean return at its cap (30k env steps)
  arm       the two-link arm             mean >= oracle - 0.1 |oracle|: the oracle MPC's     3,000   >= 4 of 5
            (benchmarks/mbrl_body.py)    mean return on the same evaluation reset seeds

Pusher's threshold was first defined as SAC at 100k env steps; it is SAC at 30k since the first
recorded run (5 seeds of SAC to 100k take ~2.5 h of this 2-core machine, more than a session may
spend on one measurement), so it asks the loop to match, in 6,000 env steps, what SAC reaches in
30,000 -- an easier bar than SAC at 100k, said wherever it is quoted.

Development and headline (benchmarks/provenance.py, Harness)
  Seeds 0-99 are development seeds: settings are chosen on them, and a run on them appends one line
  (the settings, their hash, the result) to benchmarks/devlog/mbrl-ENV.jsonl, never a result file.
  Seeds 100+ are headline seeds, the default (100-104 for both learners): such a run must start from
  committed code (run it from a `git worktree` of one commit while the tree is being edited), and it
  writes benchmarks/results/mbrl-ENV.json with the hash of every setting it used (the loop's settings
  as MbrlSettings resolves them, the catalogue's entries included; SAC's; the protocol's) and the
  development log's count of configurations tried before it, beside their in-sample numbers. It
  records nothing when a seed's process resolved other settings than the run started with, or the
  code changed while it ran. A seed also picks its evaluation episodes' reset seeds (below), so
  headline seeds meet episodes no development run played. The results recorded before the devlog
  existed (seeds 0-4, on which the settings had been chosen) are its first lines
  (scripts/devlog_from_history.py).

What runs
  The loop: motorlab.kinds.planning.MBRL (collect with MPC on the last model -> refit the ensemble ->
  evaluate; round 1 random), 5 seeds, each in its own process, 2 at a time (--loop-jobs; the
  loop plans on one torch thread, so each run has a core to itself; --loop-jobs 1: one at a time, alone
  on the machine). Its settings are the loop's DEFAULTS (motorlab's, and the env
  catalogue's per-env planner settings); the benchmark sets only: the reward to plan with ("builtin",
  or the arm's "mbrl_body:reward"), seed, device=cpu, eval_episodes=10 with parallel=10 (the 10
  evaluation episodes side by side, one batched planner call per control step), max_env_steps (the
  budget) with rounds=budget (a cap that never binds: every round collects at least one step), and
  the stopping rule until_return (+ until_every_episode on the pendulum). --loop-set KEY=VALUE
  changes any MbrlSettings field, for experiments (the JSON records it).
  SAC, two variants on the same 5 seeds as the loop, each run in its own process on one torch
  thread, 2 processes at a time, capped at 30,000 env steps:
    default  stable_baselines3.SAC("MlpPolicy", env, seed=s): SB3's defaults;
    tuned    the same with the best hyperparameters of benchmarks/sac_tune.py's Optuna search on
             development seeds (benchmarks/sac_tuned.json): rl-zoo3 has no SAC entry for these envs,
             so the loop's per-env catalogue settings meet a search of equal effort.
  Its deterministic policy is evaluated as often as the loop evaluates (every loop round: the
  episodes of ~200 env steps, e.g. Reacher 200, the arm 150; --eval-every), on 10 episodes of a
  separate env.
  Returns at fixed budgets (1,000, 3,000 and 6,000 env steps, up to the loop's budget): each
  learner's last evaluation at or before each, per seed and over seeds, beside the first hit; a run
  that stopped at the threshold before a budget carries its last evaluation, and says so.
  Evaluation episodes (both learners): seed s's episode j resets with s * 1,000,000 + 900,000 + j, the
  loop's own evaluation seeds (motorlab.planning.mbrl), the same at every evaluation; SAC seed s and loop
  seed s meet the same 10 initial states. Evaluation steps are never counted as env steps.
  The arm's oracle: motorlab.planning.oracle.oracle_episodes, MPC on the true simulator, on seed s's
  evaluation reset seeds, for each loop seed s (SAC seed s uses the same threshold). It costs ~0.2 s
  per control step, so by default it plays --oracle-episodes 3 of the 10 (the first 3) per seed;
  the threshold compares the learners' mean over 10 episodes to the oracle's mean over those 3 (the
  arm's initial states differ by a few hundredths of a radian). The JSON says which.
  The arm's torch reward is first checked equal to the env's own on random steps (float64).
  --ceiling (any env): the same oracle, but with the LOOP's planner settings (horizon, population,
  iterations, elites as the loop resolves them for the env) on all 10 evaluation episodes of every loop
  seed: the return the loop's planner reaches with a perfect model, which a learned model can only
  approach. It tells a threshold the planner cannot reach from one the model misses (Reacher, seed 1:
  ceiling -4.59 against the threshold -5.0). Reacher ~0.3 s a control step: ~7 min for 5 seeds on 2
  processes; the pendulum's 1,000-step episodes take far longer. --ceiling-from RESULT_JSON reuses
  an earlier result's ceiling where its planner settings and reset seeds are this run's (Pusher's
  takes ~25 min to play again).

Measured
  Steps to threshold, per seed: the env steps collected at the first evaluation that meets the
  threshold (SAC: a multiple of 1,000; the loop: the end of a round). The loop stops at the first
  round that meets it; SAC stops at its first evaluation that meets it (steps to threshold needs only
  the first hit), except on pusher, whose threshold is SAC's own final return (all 30k steps), and
  with --sac-full.
  Censoring: a seed that never meets the threshold within its budget (the loop: max_env_steps; SAC:
  its cap) is right-censored AT THE BUDGET, never at the steps it happened to collect; the loop's last
  round may collect past the budget (it stops after the round that reaches it), and a hit there is
  no hit within the budget: censored at the budget too. Over seeds (motorlab.stats.steps_to_threshold):
  "k of n" seeds reached it, and the Kaplan-Meier median of the steps (scipy.stats.ecdf on
  CensoredData: the smallest time where the KM estimate of the CDF reaches 0.5), or "> budget" when
  fewer than half reached it. The ratio SAC / loop of the medians (motorlab.stats.steps_ratio):
  exact; a LOWER bound (SAC's budget / the loop's median) when SAC's median is censored; an upper
  bound when the loop's is; unknown when both are.
  Intervals (motorlab.intervals, motorlab.stats): k of n with its Wilson interval; KM medians and
  the ratios with bootstrap intervals over seeds from 5 seeds on; 2-4 seeds show their range.
  Targets: the loop's k >= the table's; planning time <= 50 ms per control step for ONE env: the
  median over seeds of each run's median over its MPC collection rounds of the wall time per
  control step (planning + the env's step + recording, one env: an upper bound of one env's
  planning latency). The JSON also gives the evaluation's plan_ms_median, per env in a batched
  call of 10 envs (the call's time / 10), and the call's own time (x 10).
  Also: each loop seed's final return (its last round), rounds, env steps collected, wall time; SAC's
  whole curve per seed (every evaluation's 10 returns), its training seconds per 1k steps.

Time on this 2-core machine (measured 2026-11-26 in --quick runs on Reacher, the machine shared with other
work, load 2-4; the loop's part depends on its defaults, which are being tuned):
  SAC: ~10-13 s of wall per 1k env steps on Reacher, so 30k steps ~5-7 min a seed, 3 seeds on 2 cores
  ~10-14 min to the cap; early stopping (all but pusher) ends sooner. The pendulum's evaluations (10
  episodes of up to 1000 steps) add ~3 s each once SAC balances.
  The loop at the defaults of 2026-11-26 (CEM population 100 x 5 iterations x horizon 15, 5 probabilistic
  members, TS): one planner call for the 10 evaluation envs takes 250-370 ms (25-37 ms per env), so a
  round's evaluation costs ~0.3 s x its episodes' length: Reacher (50 steps) ~15 s, Pusher (100) ~30 s,
  the arm (150) ~45 s, cartpole (200) ~60 s, the pendulum up to ~5 min once it balances 1000 steps;
  plus collection (one env, 25-55 ms a step) and the refit (40 epochs on all data). A seed that runs
  its whole budget (rounds = budget / episode length): Reacher 60 rounds ~17 min, the arm 20 ~16 min,
  cartpole 15 ~16 min, Pusher 60 ~35 min; the pendulum depends on how soon its episodes get long.
  With 2 seeds at a time, 5 seeds take ~3x one seed when they all run to the budget; seeds that stop
  at the threshold end sooner. So at these defaults a full run fits 40 min only where most seeds stop
  early; pusher does not (make SAC once with --keep and reuse it with --sac-from).
  The arm's oracle: ~19 s per 150-step episode (~125 ms a control step), 5 seeds x 3 episodes ~2.5 min
  on 2 processes (10 episodes a seed would take ~8 min).
  Full runs at the SiLU defaults (2026-11-27, a machine ~1.6x slower than the above): Reacher with
  --ceiling 30.5 min (the ceiling 7.3, SAC 16.1, the loop 7.0: every seed stops at 1,400-2,600 steps
  but one), the arm 19.6 min (oracle 2.3, SAC 6.1, the loop 11.1). The loop plans ~35% faster with
  SiLU layers than with tanh + LayerNorm (Reacher: 15-20 ms per env in the evaluation's batch of 10).
  The pendulum with its episodes cut at 200 steps (2026-11-28, SAC reused): 58.6 min, the machine
  shared with single-threaded oracle runs for most of it; loop seeds 17-33 min each (a seed that
  balances pays 10 x 1,000 evaluation steps a round, ~2-4 min). Over the 40 min target.
Full size = the defaults (5 loop seeds, 3 SAC seeds, the budgets above); e.g.
    .venv/bin/python benchmarks/mbrl.py reacher --keep runs/bench-reacher
--quick: a smoke run (1 loop seed, 1 SAC seed to 2k steps evaluated every 500, the loop's budget 300
steps in at most 8 rounds, the arm's oracle 2 episodes), ~2-3 min.

Output: ONE JSON object on stdout (progress on stderr), also written to benchmarks/results/mbrl-ENV.json
(--quick: mbrl-ENV-quick.json, so a smoke run never overwrites a full result), with the settings, the
thresholds, every per-seed number, the statistics, the targets and whether each is met, the git commit
(and whether the tree was dirty), the date, package versions, the CPU, its cores and the load average
at the start and the end.
--keep DIR: the loop's run folders (DIR/loop-seedN) and DIR/runs.json (every run, every curve, the
oracle's returns); --sac-from DIR/runs.json takes SAC's runs (and the arm's oracle, which SAC's early
stop used) from such a file, with their settings, instead of running them again. --loop-seeds 0 --keep
DIR runs SAC alone into DIR/runs.json (no result file: there is no loop to judge).
--resume (with --keep DIR): a loop seed whose folder DIR/loop-seedN exists continues it with the
loop's own --resume (same settings, or it refuses); a finished one is read back in seconds, its wall
time the sum of its rounds' recorded times. So a benchmark that does not fit one session (pusher:
~20 min a loop seed) splits: --loop-seeds 2 --keep DIR, then --loop-seeds 5 --keep DIR --resume
--sac-from DIR/runs.json. The JSON lists the seeds read back (loop_resumed_seeds).
"""

from __future__ import annotations

import argparse
import csv
import importlib
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

from motorlab.processes import die_with_parent

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
# beside each kept loop folder (never in it: a run folder holds only the run's own files): what this
# script gave the loop (the stopping rule included); --resume reads it
LOOP_GIVEN = ".benchmark_settings.json"


def given_path(out_dir: Path) -> Path:
    return out_dir.with_name(out_dir.name + LOOP_GIVEN)
from provenance import SCIENCE_SEEDS, Harness, seed_list, write_result  # noqa: E402  (benchmarks/ is the script's folder)

# name -> env id, the reward the loop plans with, the threshold, the loop's budget, the target
# threshold "on": mean (the evaluation's mean return) or min (its worst episode); "value": a number,
# "sac_final_iqm" (SAC's IQM over seeds of its final mean return) or "oracle" (per seed, see oracle_threshold)
ENVS = {
    "pendulum": {"id": "InvertedPendulum-v5", "reward": "builtin", "on": "min", "value": 1000.0,
                 "budget": 2000, "target": 4,
                 "threshold": "1000 on all 10 evaluation episodes (their min return >= 1000)"},
    "reacher": {"id": "Reacher-v5", "reward": "builtin", "on": "mean", "value": -5.0, "budget": 3000, "target": 4,
                "threshold": "mean return >= -5.0 over the 10 evaluation episodes"},
    "cartpole": {"id": "CartpoleSwingup-v0", "reward": "builtin", "on": "mean", "value": 170.0, "budget": 3000,
                 "target": 4, "threshold": "mean return >= 170 (of 200) over the 10 evaluation episodes"},
    "pusher": {"id": "Pusher-v5", "reward": "builtin", "on": "mean", "value": "sac_final_iqm", "budget": 6000,
               "target": 3, "threshold": "mean return >= SAC's IQM over its seeds (their mean below 4 seeds) of its "
                                         "final mean return (after its cap of env steps)"},
    "arm": {"id": "mbrl_body:VerticalArmReach-v0", "reward": "mbrl_body:reward", "on": "mean", "value": "oracle",
            "budget": 3000, "target": 4,
            "threshold": "mean return >= oracle - 0.1 * |oracle|, oracle = the oracle MPC's mean return on the "
                         "seed's evaluation reset seeds (true simulator)"},
}
HEADLINE_SEEDS = list(range(100, 105))  # SCIENCE_SEEDS.headline: no setting was chosen on them
LOOP_SEEDS = len(HEADLINE_SEEDS)  # the target's n
SAC_CAP, EVAL_EPISODES = 30_000, 10
FIXED_BUDGETS = (1000, 3000, 6000)  # env steps at which both learners' returns are reported (up to the loop's budget)
SAC_VARIANTS = ("default", "tuned")  # SB3's defaults; the equal-effort Optuna search's best (benchmarks/sac_tune.py)
TUNED = HERE / "sac_tuned.json"
ORACLE_EPISODES, ORACLE_MARGIN = 3, 0.1
PLAN_MS_TARGET = 50.0
WALL_TARGET_S = 40 * 60
QUICK = {"seeds": [0], "sac_steps": 2000, "oracle_episodes": 2}
QUICK_LOOP = {"budget": 300, "rounds": 8}  # rounds: a cap on the smoke run's time (early pendulum episodes are short)
# the loop's evaluation reset seeds (motorlab.planning.mbrl.SEED_STRIDE, EVAL_OFFSET; checked in main)
SEED_STRIDE, EVAL_OFFSET = 1_000_000, 900_000


def eval_seeds(seed: int, episodes: int) -> list[int]:
    """The reset seeds of seed `seed`'s evaluation episodes: the loop's, for SAC too."""
    return [seed * SEED_STRIDE + EVAL_OFFSET + j for j in range(episodes)]


def say(msg: str) -> None:
    print(f"[mbrl-bench {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def meets(point: dict, on: str, value: float) -> bool:
    """Whether an evaluation (return_mean, return_min) meets the threshold."""
    got = point.get(f"return_{on}")
    return got is not None and got >= value


def first_hit(curve: list[dict], on: str, value: float) -> int | None:
    """Env steps at the first evaluation meeting the threshold; None if none does."""
    return next((p["env_steps"] for p in curve if meets(p, on, value)), None)


# ---------------------------------------------------------------------------------------- SAC


def evaluate(model, env, seeds: list[int]) -> list[float]:
    """The deterministic policy's return on one episode per reset seed."""
    returns = []
    for s in seeds:
        obs, _ = env.reset(seed=s)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
    return returns


def run_sac(env_id: str, seed: int, cap: int, eval_every: int, seeds: list[int], stop: dict | None,
            variant: str = "default", params: dict | None = None) -> dict:
    """SB3 SAC (its defaults, or `params`: the tuned variant's hyperparameters) for up to `cap` env
    steps, evaluated every `eval_every` steps on one episode per reset seed; with `stop` ({"on",
    "value"}) it stops at its first evaluation meeting it. Runs in its own (spawned) process, on one
    torch thread."""
    import gymnasium as gym
    import numpy as np
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import Logger

    import motorlab.envs  # noqa: F401  (registers the bundled envs: CartpoleSwingup-v0)

    torch.set_num_threads(1)
    env, eval_env = gym.make(env_id), gym.make(env_id)
    model = SAC("MlpPolicy", env, seed=seed, **(params or {}))
    model.set_logger(Logger(folder=None, output_formats=[]))  # SB3 would make an empty /tmp/SB3-<date> folder
    curve: list[dict] = []
    eval_seconds, eval_cpu = [0.0], [0.0]

    def record() -> bool:
        started, cpu = time.perf_counter(), time.process_time()
        returns = evaluate(model, eval_env, seeds)
        eval_seconds[0] += time.perf_counter() - started
        eval_cpu[0] += time.process_time() - cpu
        point = {"env_steps": model.num_timesteps, "return_mean": float(np.mean(returns)),
                 "return_std": float(np.std(returns)), "return_min": float(np.min(returns)), "returns": returns}
        curve.append(point)
        say(f"sac ({variant}) {env_id} seed {seed}: {model.num_timesteps} steps, return {point['return_mean']:.2f} "
            f"(min {point['return_min']:.2f})")
        return stop is not None and meets(point, stop["on"], stop["value"])

    class EvalEvery(BaseCallback):
        def _on_step(self) -> bool:
            return not (self.num_timesteps % eval_every == 0 and record())

    started, cpu = time.perf_counter(), time.process_time()
    model.learn(total_timesteps=cap, callback=EvalEvery())
    if not curve or curve[-1]["env_steps"] != model.num_timesteps:
        record()
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    env.close()
    eval_env.close()
    per_1k = 1000 / model.num_timesteps
    # wall time depends on what else runs on the machine; CPU time (this process's) much less
    return {"seed": seed, "variant": variant, "params": params or {}, "cap": cap, "env_steps": model.num_timesteps,
            "stopped_early": model.num_timesteps < cap, "stop": stop, "curve": curve,
            "wall_seconds": round(wall, 1), "eval_seconds": round(eval_seconds[0], 1),
            "train_seconds_per_1k_steps": round(per_1k * (wall - eval_seconds[0]), 2),
            "train_cpu_seconds_per_1k_steps": round(per_1k * (cpu - eval_cpu[0]), 2)}


def in_processes(fn, jobs: list[tuple], workers: int, label) -> list:
    """fn(*job) for every job in spawned processes, `workers` at a time; results in job order."""
    out: list = [None] * len(jobs)
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=die_with_parent,
                             initargs=(os.getpid(),)) as pool:  # a killed benchmark leaves no worker training
        futures = {pool.submit(fn, *job): i for i, job in enumerate(jobs)}
        for fut in as_completed(futures):
            out[futures[fut]] = fut.result()
            say(f"{label(out[futures[fut]])} done")
    return out


# ---------------------------------------------------------------------------------------- the arm's oracle


def run_oracle(env_id: str, seed: int, seeds: list[int], settings: dict) -> dict:
    """The oracle MPC (the true simulator) on these reset seeds; in its own process, one torch thread."""
    import numpy as np
    import torch

    from motorlab.planning.oracle import oracle_episodes

    torch.set_num_threads(1)
    started = time.perf_counter()
    result = oracle_episodes(env_id, len(seeds), seeds, seed=seed, progress=False, **settings)
    returns = [float(x) for x in np.asarray(result.returns)]
    return {"seed": seed, "reset_seeds": seeds, "returns": returns, "return_mean": float(np.mean(returns)),
            "lengths": [int(x) for x in np.asarray(result.lengths)],
            "plan_ms_median": float(np.median(result.plan_ms)), "wall_seconds": round(time.perf_counter() - started, 1),
            "settings": {**{k: getattr(result, k) for k in ("horizon", "population", "iterations", "elites", "seed")},
                         "noise_beta": settings.get("noise_beta", 0.0)}}


def oracle_threshold(oracle_mean: float) -> float:
    """Within 10% of the oracle's mean return: oracle - 0.1 |oracle| (returns may be negative)."""
    return oracle_mean - ORACLE_MARGIN * abs(oracle_mean)


def check_user_reward(name: str, steps: int = 300) -> dict:
    """The torch reward the loop plans with against the env's own, on random steps: one at a time
    and batched, in float64 (must be equal) and float32 (the model's dtype; reported)."""
    import gymnasium as gym
    import numpy as np
    import torch

    module, _, fn = ENVS[name]["reward"].partition(":")
    reward = getattr(importlib.import_module(module), fn)
    env = gym.make(ENVS[name]["id"])
    obs, _ = env.reset(seed=123)
    rows = []
    for _ in range(steps):
        action = env.action_space.sample()
        nxt, r, terminated, truncated, _ = env.step(action)
        rows.append((obs, action, nxt, r))
        obs = nxt if not (terminated or truncated) else env.reset()[0]
    env.close()
    o, a, n, r = (np.array(x, dtype=np.float64) for x in zip(*rows))
    single = np.array([float(reward(*(torch.as_tensor(x) for x in t))) for t in zip(o, a, n)])
    batched = reward(torch.as_tensor(o), torch.as_tensor(a), torch.as_tensor(n)).numpy()
    as32 = reward(*(torch.as_tensor(x, dtype=torch.float32) for x in (o, a, n))).double().numpy()
    grid = reward(*(torch.as_tensor(x).reshape(3, -1, x.shape[-1]) for x in (o, a, n))).reshape(-1).numpy()
    diff = max(np.abs(single - r).max(), np.abs(batched - r).max(), np.abs(grid - r).max())
    if diff > 1e-12:
        raise SystemExit(f"{ENVS[name]['reward']} differs from {ENVS[name]['id']}'s reward by {diff:.3g}")
    return {"steps": steps, "max_abs_diff_float64": float(diff), "bitwise_equal": bool(diff == 0.0),
            "max_abs_diff_float32": float(np.abs(as32 - r).max())}


# ---------------------------------------------------------------------------------------- the loop


def loop_settings(name: str, seed: int, budget: int, rounds: int | None, stop: float | None,
                  overrides: dict) -> dict:
    """What the benchmark gives MbrlSettings (everything else: the loop's defaults)."""
    env = ENVS[name]
    settings = {"env": env["id"], "reward": env["reward"], "seed": seed, "device": "cpu",
                "eval_episodes": EVAL_EPISODES, "parallel": EVAL_EPISODES,
                "max_env_steps": budget, "rounds": rounds or budget, "until_return": stop}
    if env["on"] == "min":
        settings["until_every_episode"] = True
    return {**settings, **overrides}


def run_loop(settings: dict, out_dir: Path) -> dict:
    """One run of motorlab's model-based loop, on one torch thread (its planner's own setting, its fitting's
    too: the same numbers at any --loop-jobs); its learning curve from out_dir/curve.csv."""
    import torch

    from motorlab.kinds.planning import MBRL, MbrlSettings

    torch.set_num_threads(1)

    given = given_path(out_dir)
    resumed = given.is_file()  # --resume: a kept folder of an earlier invocation
    if resumed and json.loads(given.read_text()) != json.loads(json.dumps(settings)):
        raise SystemExit(f"{out_dir} was run with other benchmark settings ({given}): choose another --keep")
    resolved = MbrlSettings(**settings, resume=resumed)
    started = time.perf_counter()
    if (out_dir / "summary.json").is_file():  # finished in an earlier invocation: read back, not run again
        from types import SimpleNamespace

        from motorlab.planning.mbrl import check_resumable

        check_resumable(out_dir, resolved.loop_plan(), resume=True)  # the loop's own settings, unchanged
        summary = SimpleNamespace(**json.loads((out_dir / "summary.json").read_text()))
    else:
        given.write_text(json.dumps(settings))
        summary = MBRL.run(resolved, out=out_dir, progress=False)
    wall = time.perf_counter() - started

    def num(x: str | None) -> float | None:  # an empty cell: not measured (e.g. no evaluation that round)
        return float(x) if x not in (None, "", "None", "nan") else None

    with open(out_dir / "curve.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    curve = [{"round": int(r["round"]), "env_steps": int(r["env_steps"]), "episodes": int(r["episodes"]),
              "return_mean": num(r["eval_return_mean"]), "return_std": num(r["eval_return_std"]),
              "return_min": num(r.get("eval_return_min")), "plan_ms_per_env": num(r["plan_ms_median"]),
              **{k: num(r.get(k)) for k in ("collect_return_mean", "valid_mse", "disagreement_mean",
                                            "collect_seconds", "fit_seconds", "eval_seconds")}}
             for r in rows]
    # collection rounds (2 on: MPC) one wall time per control step: planning + the env's step, for
    # min(parallel, episodes_per_round) envs side by side (1 with the default of one episode a round)
    for before, row in zip(curve, curve[1:]):
        collected = row["env_steps"] - before["env_steps"]
        row["collect_ms_per_step"] = 1000 * row["collect_seconds"] / collected if collected else None
    group = min(resolved.parallel, resolved.round_episodes())
    collect_ms = [row["collect_ms_per_step"] for row in curve[1:] if row["collect_ms_per_step"] is not None]
    return {"seed": settings["seed"], "settings": {k: v for k, v in settings.items() if k != "seed"},
            "settings_resolved": resolved.model_dump(mode="json"),
            "collect_ms_per_step_median": median(collect_ms), "collect_envs_side_by_side": group,
            "curve": curve, "rounds": len(curve), "env_steps": int(summary.env_steps),
            "plan_ms_per_env_median": summary.plan_ms_median,
            # a resumed run's rounds were run before (its curve keeps their times): its wall is theirs
            "wall_seconds": round(sum(sum(row[k] or 0 for k in ("collect_seconds", "fit_seconds", "eval_seconds"))
                                      for row in curve) if resumed else wall, 1),
            "resumed": resumed,
            "reward_source": summary.reward_source, "termination_source": summary.termination_source,
            "reached_return": summary.reached_return}


# ---------------------------------------------------------------------------------------- provenance


def result_path(name: str, quick: bool) -> Path:
    """benchmarks/results/mbrl-NAME.json (--quick: mbrl-NAME-quick.json)."""
    return RESULTS / f"mbrl-{name}{'-quick' if quick else ''}.json"


# ---------------------------------------------------------------------------------------- statistics


def median(values: list[float]) -> float | None:
    import statistics

    return statistics.median(values) if values else None


def sac_block(runs: list[dict], thresholds: dict[int, float], on: str):
    """One SAC variant's steps to the threshold (censored at its cap) and its per-seed numbers."""
    from motorlab.stats import steps_to_threshold

    steps = [first_hit(r["curve"], on, thresholds[r["seed"]]) for r in runs]
    stats = steps_to_threshold(steps, [r["cap"] for r in runs])
    return stats, {
        "seeds": [r["seed"] for r in runs], "params": runs[0].get("params", {}),
        "budget_env_steps": [r["cap"] for r in runs], "steps_to_threshold": stats.to_json(),
        "env_steps_trained": [r["env_steps"] for r in runs], "stopped_early": [r["stopped_early"] for r in runs],
        "final_return_mean": [r["curve"][-1]["return_mean"] for r in runs],
        "train_seconds_per_1k_steps": [r["train_seconds_per_1k_steps"] for r in runs],
        "train_cpu_seconds_per_1k_steps": [r["train_cpu_seconds_per_1k_steps"] for r in runs],
        "wall_seconds": [r["wall_seconds"] for r in runs]}


RATIO_MEANING = ("SAC's median steps to the threshold / the loop's (Kaplan-Meier medians); bound: exact, lower (SAC's "
                 "median censored: > its budget / the loop's median), upper (the loop's censored), unknown (both)")


def summarize(name: str, thresholds: dict[int, float], loop: list[dict], sac: list[dict], budget: int) -> dict:
    """The statistics of both learners (motorlab.stats), the targets, every per-seed number. "sac" is
    SB3's defaults; "sac_tuned" the tuned variant, where it ran."""
    from motorlab.stats import steps_ratio, steps_to_threshold

    on = ENVS[name]["on"]
    loop_steps = [first_hit(r["curve"], on, thresholds[r["seed"]]) for r in loop]
    loop_stats = steps_to_threshold(loop_steps, budget)
    learners = {}
    for variant in SAC_VARIANTS:
        runs = [r for r in sac if r.get("variant", "default") == variant]
        if runs:
            stats, block = sac_block(runs, thresholds, on)
            key = "sac" if variant == "default" else f"sac_{variant}"
            learners[key] = block
            learners[f"ratio_{key}_over_loop"] = {**steps_ratio(loop_stats, stats).to_json(), "meaning": RATIO_MEANING}
    plan = [r["plan_ms_per_env_median"] for r in loop]
    plan_known = [p for p in plan if p is not None]
    plan_median = median(plan_known)
    calls = [None if p is None else p * EVAL_EPISODES for p in plan]
    single = [r["collect_ms_per_step_median"] for r in loop if r["collect_envs_side_by_side"] == 1]
    single_median = median([x for x in single if x is not None])
    k_target = ENVS[name]["target"]
    return {
        "loop": {
            "seeds": [r["seed"] for r in loop], "budget_env_steps": budget,
            "steps_to_threshold": loop_stats.to_json(),
            "first_hit_env_steps": loop_steps,  # as the curve says, before censoring at the budget
            "final_return_mean": [r["curve"][-1]["return_mean"] for r in loop],
            "final_return_min": [r["curve"][-1]["return_min"] for r in loop],
            "env_steps_collected": [r["env_steps"] for r in loop], "rounds": [r["rounds"] for r in loop],
            "plan_ms_per_env_median": plan, "plan_ms_median": plan_median,
            "plan_call_ms_median": calls,
            "collect_ms_per_step_median": [r["collect_ms_per_step_median"] for r in loop],
            "collect_envs_side_by_side": [r["collect_envs_side_by_side"] for r in loop],
            "collect_ms_basis": "the MPC collection rounds' wall time per control step (planning, the env's step, "
                                "recording), median over rounds: one env's latency (an upper bound of its planning "
                                "time) where collect_envs_side_by_side is 1, else per step of that many envs",
            "plan_ms_basis": f"per env in a batched call of {EVAL_EPISODES} envs (the evaluation's episodes side by "
                             "side; the call's time / 10), median over a run's rounds of each round's median over "
                             "its control steps; plan_call_ms_median = x 10, the call's own time; a single env's "
                             "latency is not measured by the loop",
            "wall_seconds": [r["wall_seconds"] for r in loop],
            "reward_source": loop[0]["reward_source"], "termination_source": loop[0]["termination_source"],
        },
        **learners,
        "targets": {
            "loop_seeds": {"target": f">= {k_target} of {LOOP_SEEDS}", "k": loop_stats.solved,
                           "of": loop_stats.seeds,  # not judged on another number of seeds (--quick: 1)
                           "met": loop_stats.solved >= k_target if loop_stats.seeds == LOOP_SEEDS else None},
            # judged on one env's latency (what a user's `mpc` run waits per step), not the batched per-env share
            "plan_ms": {"target": f"<= {PLAN_MS_TARGET} ms per control step, one env (the MPC collection's wall "
                                  "time per step: planning + the env's step, an upper bound)",
                        "median": single_median, "per_env_in_a_batch_of_10_median": plan_median,
                        "met": None if single_median is None else single_median <= PLAN_MS_TARGET},
        },
    }


# ---------------------------------------------------------------------------------------- main


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("env", choices=list(ENVS), help="the env to benchmark (one per invocation)")
    parser.add_argument("--seeds", type=seed_list, default=HEADLINE_SEEDS,
                        help=f"both learners' seeds, e.g. 100-104 (the headline's, the default) or 0-4 (development: "
                             f"written to benchmarks/devlog/, never to results/); development "
                             f"{SCIENCE_SEEDS.development.start}-{SCIENCE_SEEDS.development.stop - 1}, headline "
                             f"{SCIENCE_SEEDS.headline.start}-{SCIENCE_SEEDS.headline.stop - 1}")
    parser.add_argument("--sac-only", action="store_true",
                        help="run SAC (and the arm's oracle) alone into --keep DIR/runs.json, for a later --sac-from")
    parser.add_argument("--sac", default=",".join(SAC_VARIANTS), type=lambda t: [v for v in t.split(",") if v],
                        help=f"the SAC variants to run: default (SB3's), tuned (the best of benchmarks/sac_tune.py's "
                             f"search on development seeds, from {TUNED.name}); default: both")
    parser.add_argument("--sac-steps", type=int, default=SAC_CAP, help="SAC's cap of env steps")
    parser.add_argument("--eval-every", type=int, default=None,
                        help="SAC's evaluation interval in env steps (default: the loop's round, so both learners "
                             "are evaluated equally often)")
    parser.add_argument("--sac-full", action="store_true",
                        help="train SAC to its cap even after it has met the threshold")
    parser.add_argument("--oracle-episodes", type=int, default=ORACLE_EPISODES,
                        help=f"arm: the oracle's episodes per seed (the first of its {EVAL_EPISODES} evaluation seeds)")
    parser.add_argument("--oracle-set", action="append", default=[], metavar="KEY=VALUE",
                        help="arm: an oracle_episodes setting (horizon, population, iterations, elites)")
    parser.add_argument("--ceiling", action="store_true",
                        help="also play the oracle (MPC on the true simulator) with the loop's own planner settings "
                             f"on every loop seed's {EVAL_EPISODES} evaluation episodes: what the loop's planner "
                             "reaches with a perfect model, the ceiling of a learned one")
    parser.add_argument("--ceiling-from", type=Path, default=None, metavar="RESULT_JSON",
                        help="with --ceiling: reuse the ceiling of an earlier result file (benchmarks/results/"
                             "mbrl-NAME.json) whose planner settings and reset seeds are this run's (the oracle "
                             "is seeded: a rerun plays the same episodes), instead of playing it again")
    parser.add_argument("--jobs", type=int, default=2, help="SAC and oracle processes at once (one per core)")
    parser.add_argument("--loop-jobs", type=int, default=2,
                        help="the loop's seeds at once, each in its own process (1: one at a time, alone)")
    parser.add_argument("--keep", type=Path, default=None, help="keep the loop's run folders and runs.json here")
    parser.add_argument("--resume", action="store_true",
                        help="with --keep: a loop seed whose folder is already there continues it (a finished one is "
                             "read back, not run again), so the loop's seeds can be split over invocations that each "
                             "fit a session (e.g. --seeds 100-101, then 100-104 with --sac-from); its settings "
                             "must match")
    parser.add_argument("--sac-from", type=Path, default=None,
                        help="reuse SAC's runs (and the arm's oracle) from an earlier run's runs.json")
    parser.add_argument("--quick", action="store_true", help="a smoke run: " + json.dumps({**QUICK, **QUICK_LOOP}))
    parser.add_argument("--loop-set", action="append", default=[], metavar="KEY=VALUE",
                        help="a loop setting (an MbrlSettings field), for experiments, e.g. --loop-set horizon=20")
    args = parser.parse_args(argv)
    if args.ceiling_from and not args.ceiling:
        parser.error("--ceiling-from reuses a ceiling: give --ceiling too")
    if args.resume and not args.keep:
        parser.error("--resume continues the loop folders of --keep DIR: give --keep")
    if args.sac_only and not args.keep:
        parser.error("--sac-only runs SAC alone, for a later --sac-from DIR/runs.json: give --keep DIR")
    unknown = [v for v in args.sac if v not in SAC_VARIANTS]
    if unknown or not args.sac:
        parser.error(f"--sac takes {', '.join(SAC_VARIANTS)} (comma-separated), got {args.sac}")
    if args.quick:
        for k, v in QUICK.items():
            setattr(args, k, v)
    SCIENCE_SEEDS.mode(args.seeds)  # refuses a mix of development and headline seeds before any work
    return args


def tuned_params(env_id: str) -> dict:
    """The tuned SAC's hyperparameters for env_id (benchmarks/sac_tuned.json, written by sac_tune.py from
    its search on development seeds)."""
    table = json.loads(TUNED.read_text()) if TUNED.is_file() else {}
    if env_id not in table:
        raise SystemExit(f"no tuned SAC for {env_id} in {TUNED}: run benchmarks/sac_tune.py first (it searches on "
                         "development seeds), or pass --sac default")
    return table[env_id]["params"]


def reused_ceiling(path: Path, name: str, jobs: list[tuple]) -> tuple[list[dict], dict]:
    """The ceiling runs of an earlier result file, one per job (env id, seed, reset seeds, settings),
    each checked to be the same episodes with the same planner; and where they came from."""
    saved = json.loads(path.read_text())
    if saved.get("env") != name or "ceiling" not in saved or any(saved["env_id"] != job[0] for job in jobs):
        raise SystemExit(f"{path} holds no ceiling of {name} ({jobs[0][0]}): run --ceiling without --ceiling-from")
    by_seed = {r["seed"]: r for r in saved["ceiling"]["runs"]}
    runs = []
    for _, seed, reset_seeds, settings in jobs:
        run = by_seed.get(seed)
        if run is None or run["reset_seeds"] != reset_seeds or saved["ceiling"]["settings"] != settings:
            raise SystemExit(f"{path}'s ceiling is not this run's for loop seed {seed} (another planner or reset "
                             "seeds): run --ceiling without --ceiling-from")
        runs.append(run)
        say(f"ceiling seed {seed}: mean return {run['return_mean']:.2f} (from {path})")
    return runs, {"file": str(path), "its_commit": saved.get("git", {}).get("commit"), "its_date": saved.get("date")}


def reused(args, name: str) -> tuple[list[dict], list[dict] | None]:
    """SAC's runs (and the oracle's) from an earlier runs.json; args takes on SAC's settings."""
    saved = json.loads(args.sac_from.read_text())
    if saved.get("env") != name:
        raise SystemExit(f"{args.sac_from} holds the runs of {saved.get('env')!r}, not {name!r}")
    for k in ("sac_steps", "eval_every"):
        setattr(args, k, saved["settings"][k])
    runs = {(r.get("variant", "default"), r["seed"]): r for r in saved["sac"]}
    wanted = [(v, s) for v in args.sac for s in args.seeds]
    missing = [f"{v} seed {s}" for v, s in wanted if (v, s) not in runs]
    if missing:
        raise SystemExit(f"{args.sac_from} has no SAC run for {', '.join(missing)}")
    oracle = saved.get("oracle")
    if ENVS[name]["value"] == "oracle":
        if not oracle or any(s not in {o["seed"] for o in oracle} for s in args.seeds):
            raise SystemExit(f"{args.sac_from} lacks the oracle's returns for the loop's seeds")
        args.oracle_episodes = len(oracle[0]["returns"])
    return [runs[w] for w in wanted], oracle


def write_runs(args, name: str, sac: list[dict], oracle: list[dict] | None, loop: list[dict]) -> Path:
    """--keep DIR/runs.json: every run, for --sac-from (written whole: temp file, then rename)."""
    saved = {"env": name, "settings": {"sac_steps": args.sac_steps, "eval_every": args.eval_every,
                                       "eval_episodes": EVAL_EPISODES},
             "sac": sac, "oracle": oracle, "loop": loop}
    path = args.keep / "runs.json"
    write_result(saved, path)
    return path


# MbrlSettings fields that differ between a configuration's runs (scripts/devlog_from_history.py drops them too)
PER_RUN = ("seed", "until_return", "resume")


def eval_interval(name: str, budget: int, overrides: dict) -> int:
    """The loop's env steps per round (it evaluates after each): SAC is evaluated as often. A round of
    episodes that end early (the pendulum) is shorter: capped at the loop's STEPS_PER_ROUND."""
    import gymnasium as gym

    from motorlab.kinds.planning import STEPS_PER_ROUND, MbrlSettings
    from motorlab.user_modules import split_env_id

    resolved = MbrlSettings(**loop_settings(name, 0, budget, None, None, overrides))
    module, env_id = split_env_id(ENVS[name]["id"])
    if module:  # a user's env (the arm) registers itself when its module is imported
        importlib.import_module(module)
    limit = gym.spec(env_id).max_episode_steps
    return min(resolved.round_episodes() * limit, STEPS_PER_ROUND)


def returns_at(curve: list[dict], budgets: list[int]) -> dict[str, dict]:
    """Per budget: the mean return of the run's last evaluation at or before it (None: none yet), and
    whether the run had stopped before it (it met the threshold earlier: its last evaluation, carried)."""
    out = {}
    for b in budgets:
        before = [p for p in curve if p["env_steps"] <= b]
        out[str(b)] = {"return_mean": before[-1]["return_mean"] if before else None,
                       "carried_from_stop": bool(curve) and curve[-1]["env_steps"] < b}
    return out


def fixed_budget_table(loop: list[dict], sac: list[dict], budgets: list[int]) -> dict:
    """Both learners' returns at each fixed budget, per seed, and over seeds (motorlab.intervals)."""
    from motorlab.intervals import across_seeds

    def column(runs: list[dict]) -> dict:
        per_seed = {r["seed"]: returns_at(r["curve"], budgets) for r in runs}
        out = {}
        for b in map(str, budgets):
            values = [v[b]["return_mean"] for v in per_seed.values()]
            known = [v for v in values if v is not None]
            out[b] = {"per_seed": values, "carried_from_stop": [v[b]["carried_from_stop"] for v in per_seed.values()],
                      "over_seeds": across_seeds(known).to_json() if known else None}
        return out

    table = {"loop": column(loop)}
    for variant in sorted({r.get("variant", "default") for r in sac}):
        table[f"sac_{variant}"] = column([r for r in sac if r.get("variant", "default") == variant])
    return {"budgets": budgets, "learners": table,
            "note": "the mean return of each seed's last evaluation at or before the budget; a run that stopped at "
                    "the threshold before a budget carries its last evaluation (carried_from_stop)"}


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    name, env = args.env, ENVS[args.env]
    from motorlab.kinds.planning import MbrlSettings
    from motorlab.planning import mbrl as loop_module

    if (loop_module.SEED_STRIDE, loop_module.EVAL_OFFSET) != (SEED_STRIDE, EVAL_OFFSET):
        raise SystemExit("the loop's evaluation reset seeds changed: update SEED_STRIDE, EVAL_OFFSET here")
    needed = ["max_env_steps"] + (["until_every_episode"] if env["on"] == "min" else [])
    lacking = [k for k in needed if k not in MbrlSettings.model_fields]
    if lacking:
        raise SystemExit(f"the loop lacks MbrlSettings.{', '.join(lacking)} (a budget of env steps; a threshold "
                         "on every evaluation episode), which this benchmark needs")
    seeds = list(args.seeds)
    loop_seeds = [] if args.sac_only else seeds
    budget = QUICK_LOOP["budget"] if args.quick else env["budget"]
    overrides = dict(item.split("=", 1) for item in args.loop_set)  # pydantic reads "true", "5" into their types
    oracle_settings = {k: float(v) if "." in v else int(v) for k, v in (i.split("=", 1) for i in args.oracle_set)}
    if args.eval_every is None:
        args.eval_every = eval_interval(name, budget, overrides)
    sac_params = {v: (tuned_params(env["id"]) if v == "tuned" else {}) for v in args.sac}
    budgets = [b for b in FIXED_BUDGETS if b <= budget] or [budget]
    # every setting the numbers depend on, resolved (the catalogue's entries included): its hash is the
    # configuration the development log counts, and a headline's record
    rounds = QUICK_LOOP["rounds"] if args.quick else None
    resolved = {k: v for k, v in MbrlSettings(**loop_settings(name, 0, budget, rounds, None, overrides))
                .model_dump(mode="json").items() if k not in PER_RUN}
    settings = {"env": name, "env_id": env["id"], "threshold": env["threshold"], "loop_budget": budget,
                "loop": resolved, "sac": {"cap": args.sac_steps, "eval_every": args.eval_every,
                                          "variants": sac_params, "full": args.sac_full},
                "eval_episodes": EVAL_EPISODES, "oracle": {"episodes": args.oracle_episodes, **oracle_settings},
                "fixed_budgets": budgets}
    harness = Harness("mbrl")
    run = harness.start(seeds, settings, log=f"mbrl-{name}{'-quick' if args.quick else ''}", in_sample_key="loop")
    started = time.perf_counter()
    walls: dict[str, float | None] = {}
    say(f"{name} ({env['id']}): {run.mode} run on seeds {seeds}; threshold {env['threshold']}; loop budget "
        f"{budget:,} env steps; SAC ({', '.join(args.sac)}) cap {args.sac_steps:,}, evaluated every "
        f"{args.eval_every} env steps; settings {run.settings_hash}")

    reward_check = check_user_reward(name) if env["reward"] not in ("builtin", "auto") else None
    if reward_check:
        say(f"{env['reward']} equals {env['id']}'s reward on {reward_check['steps']} random steps "
            f"(max |diff| {reward_check['max_abs_diff_float64']:.1g}; float32 {reward_check['max_abs_diff_float32']:.1g})")

    sac, oracle = (reused(args, name) if args.sac_from else (None, None))
    # 1. the arm's oracle (before SAC: SAC's early stop needs the thresholds)
    if env["value"] == "oracle" and oracle is None:
        t = time.perf_counter()
        jobs = [(env["id"], s, eval_seeds(s, args.oracle_episodes), oracle_settings) for s in seeds]
        oracle = in_processes(run_oracle, jobs, args.jobs,
                              lambda r: f"oracle seed {r['seed']}: mean return {r['return_mean']:.2f}, "
                                        f"{r['plan_ms_median']:.0f} ms/step, {r['wall_seconds']} s")
        walls["oracle"] = round(time.perf_counter() - t, 1)
    ceiling = None
    if args.ceiling:  # the loop's planner on the true simulator: its settings as the loop resolves them
        t = time.perf_counter()
        plan = MbrlSettings(**loop_settings(name, 0, budget, None, None, overrides)).plan()
        ceiling_settings = {k: plan[k] for k in ("horizon", "population", "iterations", "elites", "noise_beta")}
        jobs = [(env["id"], s, eval_seeds(s, EVAL_EPISODES), ceiling_settings) for s in loop_seeds]
        if args.ceiling_from:
            ceiling, ceiling_from = reused_ceiling(args.ceiling_from, name, jobs)
        else:
            ceiling = in_processes(run_oracle, jobs, args.jobs,
                                   lambda r: f"ceiling seed {r['seed']}: mean return {r['return_mean']:.2f} "
                                             f"(min {min(r['returns']):.2f}), {r['plan_ms_median']:.0f} ms/step")
        walls["ceiling"] = round(time.perf_counter() - t, 1)
    thresholds: dict[int, float] | None = None  # by seed: SAC seed s uses loop seed s's
    if isinstance(env["value"], float):
        thresholds = dict.fromkeys(seeds, env["value"])
    elif env["value"] == "oracle":
        by_seed = {o["seed"]: o for o in oracle}
        thresholds = {s: oracle_threshold(by_seed[s]["return_mean"]) for s in seeds}
    # 2. SAC, two processes at a time (pusher: the whole cap, its final return is the threshold)
    early = thresholds is not None and not args.sac_full
    if sac is None:
        t = time.perf_counter()
        jobs = [(env["id"], s, args.sac_steps, args.eval_every, eval_seeds(s, EVAL_EPISODES),
                 {"on": env["on"], "value": thresholds[s]} if early else None, v, sac_params[v])
                for v in args.sac for s in seeds]
        sac = in_processes(run_sac, jobs, args.jobs,
                           lambda r: f"sac ({r['variant']}) seed {r['seed']}: {r['env_steps']} steps in "
                                     f"{r['wall_seconds']} s, final return {r['curve'][-1]['return_mean']:.2f}")
        walls["sac"] = round(time.perf_counter() - t, 1)
    else:
        say(f"SAC's runs taken from {args.sac_from} (cap {args.sac_steps:,} env steps)")
    if thresholds is None:  # pusher: SAC's (defaults') IQM over seeds of its final mean return
        from motorlab.intervals import across_seeds

        defaults = [r for r in sac if r.get("variant", "default") == "default"]
        if not defaults or any(r["stopped_early"] for r in defaults):
            raise SystemExit("the threshold is SB3-default SAC's final return: run --sac default (to its cap)")
        thresholds = dict.fromkeys(seeds, across_seeds([r["curve"][-1]["return_mean"] for r in defaults]).value)
    for r in sac:  # a reused run that stopped early at another threshold cannot say when it would meet this one
        if r["stopped_early"] and first_hit(r["curve"], env["on"], thresholds[r["seed"]]) is None:
            raise SystemExit(f"SAC seed {r['seed']} stopped early (at {r['stop']}) before meeting this threshold "
                             f"({thresholds[r['seed']]:.4g}): run SAC again (or with --sac-full)")
    say("thresholds per seed: " + ", ".join(f"{s}: {x:.4g}" for s, x in thresholds.items()))
    if not loop_seeds:  # SAC alone (pusher's seeds to 30k take ~20 min): its runs for a later --sac-from
        write_runs(args, name, sac, oracle, [])
        say(f"SAC's runs in {args.keep / 'runs.json'}: run the loop with --sac-from {args.keep / 'runs.json'}")
        return

    # 3. the loop, --loop-jobs seeds at a time (each plans on one torch thread)
    t = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        kept = [s for s in loop_seeds if given_path(root / f"loop-seed{s}").is_file()]
        if kept and not args.resume:
            raise SystemExit(f"{root} already holds loop seed(s) {kept}: pass --resume to continue (or read back) "
                             "them, or choose another --keep")
        jobs = [(loop_settings(name, s, budget, rounds, thresholds[s], overrides), root / f"loop-seed{s}")
                for s in loop_seeds]
        loop = in_processes(run_loop, jobs, args.loop_jobs,
                            lambda r: f"loop seed {r['seed']}: {r['rounds']} rounds, {r['env_steps']:,} env steps in "
                                      f"{r['wall_seconds']} s, final return {fmt(r['curve'][-1]['return_mean'])} "
                                      f"(min {fmt(r['curve'][-1]['return_min'])}), plan "
                                      f"{fmt(r['plan_ms_per_env_median'])} ms/step per env")
    walls["loop"] = round(time.perf_counter() - t, 1)
    wall = time.perf_counter() - started

    stats = summarize(name, thresholds, loop, sac, budget)
    out = {
        "benchmark": "mbrl", "env": name, "env_id": env["id"], "quick": args.quick,
        "threshold": {"rule": env["threshold"], "on": f"eval_return_{env['on']}",
                      "per_seed": {str(s): x for s, x in thresholds.items()}},  # SAC seed s uses loop seed s's
        "budgets": {"loop_env_steps": budget, "sac_env_steps": args.sac_steps},
        **stats,
        "returns_at_fixed_budgets": fixed_budget_table(loop, sac, budgets),
        "loop_runs": loop,
        "sac_runs": sac,
        "settings": {
            "loop": {"given": loop[0]["settings"] if loop else None, "loop_set": overrides,
                     "processes_at_once": args.loop_jobs,
                     "note": "the rest are the loop's defaults (MbrlSettings, the env catalogue's planner settings)"},
            "sac": {"algo": "stable_baselines3.SAC('MlpPolicy', env, seed=s, **params): params {} for default (SB3's "
                            "defaults), the search's best for tuned; 1 torch thread, "
                            f"{args.jobs} processes at once", "variants": sac_params, "cap": args.sac_steps,
                    "eval_every": args.eval_every, "eval_episodes": EVAL_EPISODES, "deterministic": True,
                    "early_stop": early, "sac_full": args.sac_full},
            "eval_reset_seeds": f"seed s, episode j: s * {SEED_STRIDE} + {EVAL_OFFSET} + j (j < {EVAL_EPISODES}); the "
                                "loop's and SAC's, the same at every evaluation",
        },
        "reward_check": reward_check,
        "wall_seconds": {"total": round(wall, 1), **walls}, "wall_target_seconds": WALL_TARGET_S,
    }
    if oracle is not None:
        out["oracle"] = {"runs": oracle, "episodes_per_seed": args.oracle_episodes,
                         "settings": oracle_settings or "oracle_episodes' defaults",
                         "note": f"per loop seed s, the oracle plays the first {args.oracle_episodes} of s's "
                                 f"{EVAL_EPISODES} evaluation reset seeds; the threshold compares the learners' mean "
                                 f"over all {EVAL_EPISODES} with the oracle's mean over those"}
    if ceiling is not None:
        by_seed = {r["seed"]: r for r in ceiling}
        out["ceiling"] = {
            "runs": ceiling, "settings": ceiling_settings,
            "return_mean": [by_seed[s]["return_mean"] for s in loop_seeds],
            "meets_threshold": [meets({"return_mean": by_seed[s]["return_mean"],
                                       "return_min": min(by_seed[s]["returns"])}, env["on"], thresholds[s])
                                for s in loop_seeds],
            "note": "the oracle (motorlab.planning.oracle: MPC on the true simulator) with the loop's planner "
                    f"settings, on each loop seed's {EVAL_EPISODES} evaluation reset seeds: the return the loop's "
                    "planner reaches with a perfect model; a learned model's loop can match it, not beat it "
                    "(but for the planner's own randomness)"}
    if args.ceiling_from:
        out["ceiling_from"] = ceiling_from
    if args.sac_from:
        out["sac_from"] = str(args.sac_from)
    if args.resume:
        out["loop_resumed_seeds"] = [r["seed"] for r in loop if r["resumed"]]
    if args.keep:
        out["runs"] = str(write_runs(args, name, sac, oracle, loop))
    # each seed's process resolved the loop's settings itself: the run's settings with those, checked equal
    used = {f"loop seed {r['seed']}": {**settings, "loop": {k: v for k, v in r["settings_resolved"].items()
                                                            if k not in PER_RUN}} for r in loop}
    kept = ("loop", "targets", "returns_at_fixed_budgets", "threshold", *(k for k in out if k.startswith(("sac", "ratio"))))
    result = out if run.mode == "headline" else {k: out[k] for k in kept if k != "sac_runs"}
    run.finish(result, file=result_path(name, args.quick).stem, used=used)


if __name__ == "__main__":
    main()
