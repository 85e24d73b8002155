"""motorlab's model-based defaults on generated bodies no one tuned them on (issue 53, item 3).

    .venv/bin/python benchmarks/mbrl_bodies.py [--bodies 100-109] [--only 100,101] [--keep DIR] [--resume] [--quick]

The bodies: benchmarks/bodies.py's generated planar arms (2-4 links, random lengths, masses, damping and
torques; half vertical, with gravity), reaching a new random target every episode. A body's generator
seed is the seed the harness judges (benchmarks/provenance.py, Harness("mbrl_bodies")): development
bodies 0-99 (settings are chosen on them; a run writes one line to benchmarks/devlog/mbrl_bodies.jsonl),
headline bodies 100-999, of which this benchmark reports 100-109 (benchmarks/results/mbrl_bodies.json,
at a commit, with the hash of every setting and the count of configurations the devlog tried). A fix
that a headline prompted is judged on fresh bodies, e.g. --bodies 110-119
(benchmarks/results/mbrl_bodies-110-119.json, beside the first).
Odd seeds are muscle arms (bodies:GeneratedMuscleArm-sN-v0: an antagonist pair of MuJoCo muscles per
joint, excitations in [0, 1]), even seeds motor arms (bodies:GeneratedArm-sN-v0): 5 and 5 of 100-109.

Per body, on the same 10 evaluation episodes (reset seeds N * 1,000,000 + 900,000 + j, j < 10: the loop's
own evaluation seeds with its seed = N, so a headline body meets episodes no development run played):
  random   uniform random actions (the action space seeded with each episode's reset seed)
  oracle   motorlab.planning.oracle.oracle_episodes: CEM on the true simulator, its defaults (horizon 15,
           population 100, 3 iterations, 10 elites), the planner seeded with N
  one-shot as a user runs it, through motorlab's Python API (the CLI's steps): dynamics collect (400
           random episodes) -> dynamics fit --learn-reward -> mpc with the user's torch reward
           (--reward bodies:reward) and with the learned reward head (--reward learned)
  loop     motorlab mbrl --reward bodies:reward, 3,000 env steps (max_env_steps; rounds never bind),
           its evaluation after the round that reaches the budget (evaluated every 5th round and the
           last: --eval-every 5, which changes no model)
No catalogue entry and no per-body setting: motorlab's defaults everywhere, except what a benchmark must
give (recorded, the same for every body): the env, the reward, episodes, seeds, device=cpu, parallel=10
(the 10 evaluation episodes in one batched planner call), workers=1 (one core per body).

Score per body and method: the share of the gap between random actions and the oracle it closes,
(R - R_random) / (R_oracle - R_random) (None where the oracle is no better than random). Targets (the
issue's): the loop >= 0.70, the one-shot path with the user's reward >= 0.60, with the learned reward
>= 0.50, each on >= 8 of the 10 headline bodies (the issue gives a count for the loop only; the one-shot
targets are judged the same way here, and the median share is reported beside k of n, with k of n's
Wilson interval). "met" is judged only on the 10 headline bodies (null on development bodies).

Compute (2 cores): bodies run --jobs (2) at a time, each in its own process on one torch thread.
Measured 2026-11-29 on this 2-core machine, headline bodies 100-105 two at a time with the loop
evaluated every 5th round: 5-9.5 min a body (the oracle 1.5-4 min, the loop 2.3-3.7 min, collect + fit
+ both mpc runs 1-2.2 min; the first pair shared the cores with other work), 21.7 min for the six. So 10 bodies take ~36 min on
2 processes; split them to stay well inside an hour, e.g. --only 100-105 --keep DIR, then --only
106-109 --keep DIR --resume (the last invocation, with every body of --bodies finished, records).
An idle machine is faster. --quick (a smoke run: 20 collected episodes, 5 epochs, 2 evaluation
episodes, a 400-step loop, a cheap oracle): ~1.5 min for 2 bodies; development bodies only, logged to
benchmarks/devlog/mbrl_bodies-quick.jsonl.

--keep DIR: each body's run folders (DIR/body-sN/{collect,fit,mpc-user,mpc-learned,mbrl}) and its result
(DIR/body-sN/body.json); --resume reads a finished body back (its settings and commit checked equal to
this run's) and runs an unfinished one again from scratch. --only: run these bodies of --bodies now and
record nothing until all are finished (prints what is done and what is left).

Output: ONE JSON object on stdout (progress on stderr): the devlog line (development), or the result
file's content (headline), or a partial summary (--only with bodies left).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from motorlab.processes import die_with_parent

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from provenance import Harness, git_state, seed_list  # noqa: E402  (benchmarks/ is the script's folder)

NAME = "mbrl_bodies"
HEADLINE_BODIES = list(range(100, 110))
SEED_STRIDE, EVAL_OFFSET = 1_000_000, 900_000  # motorlab.planning.mbrl's evaluation reset seeds (checked in main)
TARGETS = {"loop": 0.70, "mpc_user": 0.60, "mpc_learned": 0.50}
K_NEEDED, N_JUDGED = 8, 10
BODY_RESULT = "body.json"


@dataclass(frozen=True)
class Budgets:
    """The benchmark's own numbers, the same for every body."""

    eval_episodes: int = 10
    collect_episodes: int = 400
    fit_epochs: int | None = None  # None: dynamics fit's default
    loop_env_steps: int = 3000
    # the loop evaluated every 5th round (1,000 env steps) and its last: evaluating its 10 episodes every
    # round was ~3/4 of the loop's time, and evaluation changes no model (mbrl --eval-every)
    loop_eval_every: int = 5
    oracle: tuple[tuple[str, int], ...] = (("horizon", 15), ("population", 100), ("iterations", 3), ("elites", 10))
    # development only (a headline runs motorlab's defaults): settings tried on a step, (step, key, value),
    # and whether the loop runs (a search of the one-shot path's settings can leave its ~10 min out)
    overrides: tuple[tuple[str, str, str], ...] = ()
    loop: bool = True
    one_shot: bool = True  # development only: False leaves collect -> fit -> mpc out (a search of the loop's)


FULL = Budgets()
QUICK = Budgets(eval_episodes=2, collect_episodes=20, fit_epochs=5, loop_env_steps=400, loop_eval_every=1,
                oracle=(("horizon", 10), ("population", 50), ("iterations", 2), ("elites", 5)))


def say(msg: str) -> None:
    print(f"[mbrl-bodies {time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def muscles_of(seed: int) -> bool:
    """Odd generator seeds are muscle arms, even ones motor arms."""
    return seed % 2 == 1


def body_env(seed: int) -> str:
    import bodies

    return f"bodies:{bodies.env_id(seed, muscles_of(seed))}"


def eval_resets(seed: int, episodes: int) -> list[int]:
    """The evaluation episodes' reset seeds: the loop's own (its seed = the body's), for every method."""
    return [seed * SEED_STRIDE + EVAL_OFFSET + j for j in range(episodes)]


# ---------------------------------------------------------------------------------------- settings

# where a step reads the previous step's folder: recorded as this placeholder (the folder differs per run)
FROM_PREVIOUS = "<the previous step's folder>"


def step_fields(seed: int, budgets: Budgets) -> dict[str, dict[str, Any]]:
    """What the benchmark gives each motorlab step (everything else: motorlab's defaults)."""
    env, n = body_env(seed), budgets.eval_episodes
    mpc = {"env": env, "model": FROM_PREVIOUS, "episodes": n, "parallel": n, "seed": eval_resets(seed, 1)[0],
           "device": "cpu"}
    fit = {"transitions": FROM_PREVIOUS, "learn_reward": True, "device": "cpu"}
    if budgets.fit_epochs is not None:
        fit["epochs"] = budgets.fit_epochs
    fields = {
        "collect": {"env": env, "episodes": budgets.collect_episodes, "workers": 1},
        "fit": fit,
        "mpc_user": {**mpc, "reward": "bodies:reward"},
        "mpc_learned": {**mpc, "reward": "learned"},
        "mbrl": {"env": env, "reward": "bodies:reward", "seed": seed, "device": "cpu", "eval_episodes": n,
                 "parallel": n, "max_env_steps": budgets.loop_env_steps, "rounds": budgets.loop_env_steps,
                 "eval_every": budgets.loop_eval_every},
    }
    for step, key, value in budgets.overrides:  # pydantic reads "1", "true" into the field's type
        targets = ("mpc_user", "mpc_learned") if step == "mpc" else (step,)
        for name in targets:
            fields[name][key] = json.loads(value) if value.startswith("[") else value  # a list: hidden=[200,200]
    if not budgets.loop:
        del fields["mbrl"]
    if not budgets.one_shot:
        for name in ("collect", "fit", "mpc_user", "mpc_learned"):
            del fields[name]
    return fields


def kinds() -> dict[str, Any]:
    from motorlab.kinds.dynamics import DYNAMICS_COLLECT, DYNAMICS_FIT
    from motorlab.kinds.planning import MBRL, MPC

    return {"collect": DYNAMICS_COLLECT, "fit": DYNAMICS_FIT, "mpc_user": MPC, "mpc_learned": MPC, "mbrl": MBRL}


def resolved_settings(seed: int, budgets: Budgets) -> dict[str, Any]:
    """Every setting a body's run uses: each motorlab step's settings as motorlab resolves them (its
    defaults, and a catalogue entry if the env had one), the oracle's and random actions'."""
    from motorlab.api import running

    step = {name: running.settings(kinds()[name], **fields).model_dump(mode="json")  # type: ignore[arg-type]
            for name, fields in step_fields(seed, budgets).items()}
    resets = eval_resets(seed, budgets.eval_episodes)
    return {**step, "oracle": {**dict(budgets.oracle), "seed": seed, "reset_seeds": resets},
            "random": {"reset_seeds": resets, "actions": "action_space.sample(), the space seeded with the reset seed"}}


BODY_ENV, BODY_SEED = "<the body's env>", "<the body's seed>"
BODY_RESETS, BODY_FIRST_RESET = "<the body's evaluation reset seeds>", "<the body's first evaluation reset seed>"


def body_free(seed: int, settings: dict[str, Any]) -> dict[str, Any]:
    """A body's resolved settings with what names the body (its env id, its seeds) replaced by placeholders:
    the same for every body when motorlab gives none of them settings of its own."""
    env, resets = body_env(seed), settings["oracle"]["reset_seeds"]

    def swap(x: Any) -> Any:
        if isinstance(x, dict):
            return {k: swap(v) for k, v in x.items()}
        if isinstance(x, list):
            return BODY_RESETS if x == resets else [swap(v) for v in x]
        return BODY_ENV if x == env else x

    out = swap(settings)
    out["oracle"]["seed"] = BODY_SEED
    if "mbrl" in out:
        out["mbrl"]["seed"] = BODY_SEED
    for name in ("mpc_user", "mpc_learned"):
        if name in out:
            out[name]["seed"] = BODY_FIRST_RESET
    return out


def generator() -> dict[str, Any]:
    """What makes the bodies (a changed generator is another configuration, as a changed setting is)."""
    import bodies

    return {"ranges": asdict(bodies.RANGES), "episode_steps": bodies.EPISODE_STEPS, "control_dt": bodies.CONTROL_DT,
            "action_cost": bodies.ACTION_COST, "muscle_force_margin": bodies.MUSCLE_FORCE_MARGIN,
            "target_min_reach": bodies.TARGET_MIN_REACH, "muscles": "odd generator seeds"}


def run_settings(per_body: dict[str, Any], budgets: Budgets) -> dict[str, Any]:
    """The run's settings, the same whichever bodies it runs (so the devlog counts configurations, not bodies):
    the budgets, the generator, and every body's resolved settings with the body named by placeholders.
    --jobs is not one: each body runs alone on one thread."""
    return {"budgets": asdict(budgets), "generator": generator(), "per_body": per_body,
            "per_body_placeholders": {BODY_ENV: "bodies:GeneratedArm-sN-v0 (even N), bodies:GeneratedMuscleArm-sN-v0 "
                                                "(odd N)", BODY_SEED: "N",
                                      BODY_RESETS: f"N * {SEED_STRIDE} + {EVAL_OFFSET} + j, j < eval_episodes",
                                      BODY_FIRST_RESET: f"N * {SEED_STRIDE} + {EVAL_OFFSET}"}}


def common_settings(bodies: list[int], resolved: dict[int, dict[str, Any]]) -> dict[str, Any]:
    """The bodies' shared body-free settings; refused where a body has settings of its own (a catalogue entry)."""
    free = {s: body_free(s, resolved[s]) for s in bodies}
    first = free[bodies[0]]
    for s in bodies[1:]:
        if free[s] != first:
            differ = sorted(k for k in first if free[s].get(k) != first[k])
            raise SystemExit(f"body {s} resolves other settings than body {bodies[0]} ({', '.join(differ)}): a body "
                             "must go through motorlab's defaults, with no settings of its own")
    return first


# ---------------------------------------------------------------------------------------- one body


def random_returns(env_id: str, resets: list[int]) -> list[float]:
    import gymnasium as gym

    env = gym.make(env_id)
    out = []
    for s in resets:
        env.reset(seed=s)
        env.action_space.seed(s)
        total, done = 0.0, False
        while not done:
            _, r, terminated, truncated, _ = env.step(env.action_space.sample())
            total += float(r)
            done = terminated or truncated
        out.append(total)
    env.close()
    return out


def oracle_returns(env_id: str, seed: int, resets: list[int], planner: dict[str, int]) -> tuple[list[float], float]:
    """The oracle's returns and its median planning time per control step (ms)."""
    import numpy as np

    from motorlab.planning.oracle import oracle_episodes

    result = oracle_episodes(env_id, len(resets), resets, seed=seed, **planner)
    return [float(x) for x in result.returns], float(np.median(result.plan_ms))


def loop_curve(folder: Path) -> list[dict[str, float | None]]:
    import csv

    def num(x: str | None) -> float | None:
        return float(x) if x not in (None, "", "None", "nan") else None

    with open(folder / "curve.csv", newline="") as f:
        return [{"round": int(r["round"]), "env_steps": int(r["env_steps"]), "return_mean": num(r["eval_return_mean"]),
                 "return_min": num(r.get("eval_return_min"))} for r in csv.DictReader(f)]


def run_body(seed: int, budgets: Budgets, folder: Path, baselines: dict[str, list[float]] | None = None
             ) -> dict[str, Any]:
    """One body, every method, in this (spawned) process on one torch thread; writes folder/body.json."""
    import bodies
    import numpy as np
    import torch

    from motorlab.api import running

    torch.set_num_threads(1)
    env_id, resets = body_env(seed), eval_resets(seed, budgets.eval_episodes)
    settings = resolved_settings(seed, budgets)  # resolved here too: the run checks it equals the parent's
    fields, walls, returns = step_fields(seed, budgets), {}, {}
    folder.mkdir(parents=True)

    def timed(name: str, fn, *args):
        start = time.perf_counter()
        out = fn(*args)
        walls[name] = round(time.perf_counter() - start, 1)
        return out

    def step(name: str, previous: Path | None = None):
        given = {k: (str(previous) if v == FROM_PREVIOUS else v) for k, v in fields[name].items()}
        checked = running.settings(kinds()[name], **given)
        return timed(name, running.run, kinds()[name], checked, folder / name.replace("_", "-"), False)

    if baselines is not None:  # random's and the oracle's returns of an earlier run of these episodes
        returns["random"], returns["oracle"], plan_ms = baselines["random"], baselines["oracle"], baselines["plan_ms"]
    else:
        returns["random"] = timed("random", random_returns, env_id, resets)
        returns["oracle"], plan_ms = timed("oracle", oracle_returns, env_id, seed, resets, dict(budgets.oracle))
    say(f"body {seed}: random {np.mean(returns['random']):.2f}")
    say(f"body {seed}: oracle {np.mean(returns['oracle']):.2f} ({plan_ms:.0f} ms a step)")
    model = None
    if budgets.one_shot:
        data = step("collect")
        model = step("fit", data.path)
        for name in ("mpc_user", "mpc_learned"):
            result = step(name, model.path)
            returns[name] = [float(x) for x in np.load(result.path / "episodes.npz")["returns"]]
            say(f"body {seed}: {name} {np.mean(returns[name]):.2f}")
    curve: list[dict[str, float | None]] = []
    if budgets.loop:
        curve = loop_curve(step("mbrl").path)
        say(f"body {seed}: loop {curve[-1]['return_mean']:.2f} after {curve[-1]['env_steps']} env steps")
    means: dict[str, float | None] = {k: float(np.mean(v)) for k, v in returns.items()}
    means["loop"] = curve[-1]["return_mean"] if curve else None
    out = {"seed": seed, "env_id": env_id, "muscles": muscles_of(seed),
           "body": asdict(bodies.generate(seed, muscles_of(seed))), "eval_reset_seeds": resets,
           "return_mean": means, "gap_closed": gap_shares(means), "returns": returns,
           "loop": {"curve": curve, "env_steps": curve[-1]["env_steps"], "rounds": len(curve)} if curve else None,
           "oracle_plan_ms_median": plan_ms, "valid_mse": model.summary.get("valid_mse") if model else None,
           "baselines_reused": baselines is not None,
           "wall_seconds": {**walls, "total": round(sum(walls.values()), 1)},
           "settings": settings, "git": git_state()}
    write_json(out, folder / BODY_RESULT)
    return out


def gap_shares(means: dict[str, float | None]) -> dict[str, float | None]:
    """(R - R_random) / (R_oracle - R_random) per method; None where the oracle does not beat random."""
    gap = means["oracle"] - means["random"]
    return {k: (None if gap <= 0 or means.get(k) is None else (means[k] - means["random"]) / gap) for k in TARGETS}


def write_json(out: dict, path: Path) -> None:
    from provenance import write_result

    write_result(out, path)


# ---------------------------------------------------------------------------------------- over bodies


def judge(results: list[dict[str, Any]], headline: bool) -> dict[str, Any]:
    """Per method: every body's share, the median, k of n meeting the target (Wilson interval), met."""
    from motorlab.intervals import wilson

    n = len(results)
    out = {}
    for method, target in TARGETS.items():
        shares = [r["gap_closed"][method] for r in results]
        k = sum(1 for s in shares if s is not None and s >= target)
        judged = headline and n == N_JUDGED
        out[method] = {"target": f">= {target} of the gap on >= {K_NEEDED} of {N_JUDGED} headline bodies",
                       "per_body": {str(r["seed"]): s for r, s in zip(results, shares)},
                       "median": statistics.median([s for s in shares if s is not None]) if any(
                           s is not None for s in shares) else None,
                       "k": k, "of": n, "k_of_n_wilson_95": list(wilson(k, n)),
                       "met": (k >= K_NEEDED) if judged else None}
    return out


def summarize(results: list[dict[str, Any]], headline: bool, budgets: Budgets) -> dict[str, Any]:
    return {
        "bodies": [r["seed"] for r in results],
        "targets": judge(results, headline),
        "return_mean": {str(r["seed"]): r["return_mean"] for r in results},
        "per_body": [{k: r[k] for k in ("seed", "env_id", "muscles", "body", "eval_reset_seeds", "return_mean",
                                        "gap_closed", "returns", "loop", "oracle_plan_ms_median", "valid_mse",
                                        "wall_seconds")} for r in results],
        "budgets": asdict(budgets),
        "wall_seconds_per_body": {str(r["seed"]): r["wall_seconds"]["total"] for r in results},
        "note": "gap_closed = (R - R_random) / (R_oracle - R_random) on the body's evaluation episodes; loop = its "
                "evaluation after the round that reached the budget of env steps",
    }


# ---------------------------------------------------------------------------------------- main


def result_file(bodies: list[int]) -> str:
    """The headline's file: results/mbrl_bodies.json for the bodies this benchmark reports (100-109), else
    results/mbrl_bodies-FIRST-LAST.json: a fix prompted by what one headline showed is judged on bodies
    no run has shown, beside that headline rather than over it."""
    return NAME if bodies == HEADLINE_BODIES else f"{NAME}-{bodies[0]}-{bodies[-1]}"


def parse_seeds(text: str) -> list[int]:
    """"100-109", "0,1,5", "0-2,7" -> a sorted list without repeats."""
    return sorted(seed_list(text))


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bodies", type=parse_seeds, default=HEADLINE_BODIES,
                        help="the generator seeds judged together (default the headline 100-109); development: 0-99")
    parser.add_argument("--only", type=parse_seeds, default=None,
                        help="run only these of --bodies now (needs --keep); records when all are finished")
    parser.add_argument("--jobs", type=int, default=2, help="bodies at once, each in its own process")
    parser.add_argument("--keep", type=Path, default=None, help="keep each body's run folders and result here")
    parser.add_argument("--resume", action="store_true", help="with --keep: read finished bodies back")
    parser.add_argument("--quick", action="store_true", help=f"a smoke run: {asdict(QUICK)}")
    parser.add_argument("--set", action="append", default=[], metavar="STEP.KEY=VALUE", dest="overrides",
                        help="development bodies only: try a setting on a step (collect, fit, mpc, mbrl), e.g. "
                             "collect.noise_beta=1; a headline runs motorlab's defaults")
    parser.add_argument("--no-loop", action="store_true",
                        help="development bodies only: leave the loop out (a search of the one-shot path's settings)")
    parser.add_argument("--no-one-shot", action="store_true",
                        help="development bodies only: leave collect -> fit -> mpc out (a search of the loop's settings)")
    parser.add_argument("--baselines-from", type=Path, default=None, metavar="DIR",
                        help="take random's and the oracle's returns from DIR/body-sN/body.json (a --keep of an "
                             "earlier run on the same episodes, generator and oracle), instead of playing them again")
    args = parser.parse_args(argv)
    overrides = []
    for item in args.overrides:
        key, eq, value = item.partition("=")
        step, dot, field = key.partition(".")
        if not (eq and dot and step in ("collect", "fit", "mpc", "mbrl")):
            parser.error(f"--set {item!r}: give STEP.KEY=VALUE, STEP one of collect, fit, mpc, mbrl")
        overrides.append((step, field, value))
    args.overrides = tuple(overrides)
    if (args.resume or args.only) and not args.keep:
        parser.error("--resume and --only work on the bodies kept in --keep DIR: give --keep")
    if args.only and not set(args.only) <= set(args.bodies):
        parser.error(f"--only {args.only} must be among --bodies {args.bodies}")
    return args


def read_back(seed: int, folder: Path, settings: dict[str, Any], headline: bool) -> dict[str, Any]:
    """A finished body of an earlier invocation, checked to be this run's (settings; commit for a headline)."""
    saved = json.loads((folder / BODY_RESULT).read_text())
    if saved["settings"] != settings:
        raise SystemExit(f"{folder} was run with other settings: choose another --keep")
    now = git_state()
    if headline and (saved["git"].get("commit") != now.get("commit") or saved["git"].get("dirty")):
        raise SystemExit(f"{folder} was run at another commit ({saved['git'].get('commit')}) or with uncommitted "
                         "changes: a headline's bodies run at one commit")
    say(f"body {seed}: read back from {folder}")
    return saved


def baselines_of(seed: int, root: Path | None, budgets: Budgets) -> dict[str, Any] | None:
    """Random's and the oracle's returns for this body from an earlier run kept in root, checked to be
    the same episodes, generator and oracle settings; None without root."""
    if root is None:
        return None
    path = root / f"body-s{seed}" / BODY_RESULT
    if not path.is_file():
        raise SystemExit(f"--baselines-from: no {path}")
    saved = json.loads(path.read_text())
    now = resolved_settings(seed, budgets)
    if saved["settings"]["oracle"] != now["oracle"] or saved["settings"]["random"] != now["random"] or \
            saved["body"] != json.loads(json.dumps(asdict(__import__("bodies").generate(seed, muscles_of(seed))))):
        raise SystemExit(f"--baselines-from: {path} played other episodes, another body or another oracle")
    return {"random": saved["returns"]["random"], "oracle": saved["returns"]["oracle"],
            "plan_ms": saved["oracle_plan_ms_median"]}


def in_processes(jobs: list[tuple], workers: int) -> dict[int, dict[str, Any]]:
    out = {}
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=die_with_parent,
                             initargs=(os.getpid(),)) as pool:  # a killed benchmark leaves no worker training
        futures = {pool.submit(run_body, *job): job[0] for job in jobs}
        for fut in as_completed(futures):
            r = fut.result()
            out[r["seed"]] = r
            say(f"body {r['seed']} done in {r['wall_seconds']['total']} s: gap closed " +
                ", ".join(f"{k} {v:.2f}" if v is not None else f"{k} -" for k, v in r["gap_closed"].items()))
    return out


def main(argv: list[str] | None = None) -> None:
    args = parse(argv)
    from motorlab.planning import mbrl as loop_module

    if (loop_module.SEED_STRIDE, loop_module.EVAL_OFFSET) != (SEED_STRIDE, EVAL_OFFSET):
        raise SystemExit("the loop's evaluation reset seeds changed: update SEED_STRIDE, EVAL_OFFSET here")
    # motorlab's own child processes import `bodies` (MOTORLAB_IMPORTS): they need benchmarks/ on their path
    os.environ["PYTHONPATH"] = os.pathsep.join([str(HERE), *filter(None, [os.environ.get("PYTHONPATH")])])
    from dataclasses import replace

    budgets = replace(QUICK if args.quick else FULL, overrides=args.overrides, loop=not args.no_loop,
                      one_shot=not args.no_one_shot)
    harness = Harness(NAME)
    mode = harness.seeds.mode(args.bodies)
    if mode == "headline" and (args.overrides or args.no_loop or args.no_one_shot
                                  or args.baselines_from):
        raise SystemExit("a headline runs motorlab's defaults on every method, from scratch: --set, --no-loop, "
                         "--no-one-shot and --baselines-from are for development bodies (0-99)")
    if args.quick and mode == "headline":
        raise SystemExit("--quick is a smoke run: run it on development bodies (0-99)")
    per_body = common_settings(args.bodies, {s: resolved_settings(s, budgets) for s in args.bodies})
    settings = run_settings(per_body, budgets)
    # in-sample runs: development runs whose steps resolved the same settings, whatever --set said to get there
    run = harness.start(args.bodies, settings, log=f"{NAME}-quick" if args.quick else None, in_sample_key="per_body")
    headline = mode == "headline"
    now = args.only or args.bodies
    say(f"{mode} bodies {args.bodies}" + (f", running {now} now" if args.only else "") + f"; budgets {asdict(budgets)}")
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        results, jobs = {}, []
        for seed in args.bodies:
            folder = root / f"body-s{seed}"
            if (folder / BODY_RESULT).is_file() and args.resume:
                results[seed] = read_back(seed, folder, resolved_settings(seed, budgets), headline)
            elif folder.exists() and not args.resume:
                raise SystemExit(f"{folder} exists: pass --resume to read it back (or run it again), or choose "
                                 "another --keep")
            elif seed in now:
                if folder.exists():  # an unfinished body of an earlier invocation: from scratch
                    shutil.rmtree(folder)
                jobs.append((seed, budgets, folder, baselines_of(seed, args.baselines_from, budgets)))
        started = time.perf_counter()
        results.update(in_processes(jobs, args.jobs) if jobs else {})
        wall = round(time.perf_counter() - started, 1)
    left = [s for s in args.bodies if s not in results]
    if left:
        print(json.dumps({"benchmark": NAME, "status": "partial: nothing recorded", "mode": mode,
                          "finished": sorted(results), "left": left, "wall_seconds": wall,
                          "next": f"--only {','.join(map(str, left))} --keep {args.keep} --resume",
                          "gap_closed": {str(s): r["gap_closed"] for s, r in sorted(results.items())}}, indent=2))
        return
    ordered = [results[s] for s in args.bodies]
    # each body as its own process resolved it (or an earlier invocation's, read back): the run's settings
    used = {f"body {r['seed']}": {**settings, "per_body": body_free(r["seed"], r["settings"])} for r in ordered}
    result = {**summarize(ordered, headline, budgets), "quick": args.quick, "jobs": args.jobs,
              "wall_seconds_this_invocation": wall,
              "read_back": sorted(set(args.bodies) - {j[0] for j in jobs})}
    run.finish(result, result_file(args.bodies), used=used)


if __name__ == "__main__":
    main()
