"""The model-based loop (PETS, Chua et al. 2018; mbrl-lib's `pets` example), round by round.

Round 1 collects episodes with random actions; every round then
  1. refits the forward model on all transitions so far, warm-started from the last round's model,
  2. evaluates MPC on that model (`eval_episodes`, fixed reset seeds, not added to the data),
  3. and the next round collects its episodes with that planner.
So the learning curve is the planner's return against the env steps collected so far.

Every round writes `rounds/NN/`: transitions.npz (its episodes), model/ (the refit model), and
round.json (the planner settings it collected with, its numbers), last, marking the round done.
A killed loop resumes (`resume=True`) from the first round without round.json, redoing only
the phase that was cut: collection and fitting are deterministic given the seed, so a resumed
loop ends with the numbers an uninterrupted one would have.

Numerical faults: episodes that ended on one (a diverging simulation) and the non-finite predictions
and rewards the planner rejected are counted per round (round.json, curve.csv's episode_faults and
planner_faults; a round's collection keeps its own in its transitions' meta, so a resumed loop counts
them too) and listed in the run's faults.log.

Held-out episodes: of the episodes numbered 0, 1, 2, ... across rounds, every `holdout_every`-th
(see `holdout`) is never trained on. "valid_mse" is the model's error on all of them so far,
"valid_mse_first" on those of the first round that held one out, the same set every round.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from motorlab import trackers
from motorlab.dynamics.collection import collect_transitions, episode_arrays
from motorlab.dynamics.layouts import env_layout
from motorlab.dynamics.model import MODEL_JSON, ForwardModel, load_model
from motorlab.dynamics.train import evaluate_rows, fit_model
from motorlab.dynamics.transitions import TRANSITIONS, Transitions, concatenate, load_transitions
from motorlab.envs import EnvConfig, env_record, make_env
from motorlab.errors import MotorlabError
from motorlab.planning.mpc import FaultCounts
from motorlab.planning.mpc_episodes import (
    MPCEpisodes,
    build_policy,
    planner_fault_line,
    require_plannable,
    run_episodes,
)
from motorlab.runs import MetricsWriter, read_json, write_json

ROUND_JSON = "round.json"
LOOP_JSON = "loop.json"
CURVE = "curve.csv"
# reset seeds: collected episode g of loop seed s resets with s * SEED_STRIDE + g, evaluation episode
# j with s * SEED_STRIDE + EVAL_OFFSET + j (the same every round, so rounds are compared on one set)
SEED_STRIDE, EVAL_OFFSET = 1_000_000, 900_000


@dataclass
class RoundRecord:
    """One round's numbers: a row of curve.csv."""

    round: int
    env_steps: int  # collected so far, this round's included
    episodes: int  # collected so far
    collect_return_mean: float  # this round's collected episodes (random in round 1)
    eval_return_mean: float | None
    eval_return_std: float | None
    eval_return_min: float | None  # the worst evaluation episode (a threshold "on every episode" reads it)
    valid_mse: float | None
    valid_mse_first: float | None
    plan_ms_median: float | None  # per env per control step, this round's evaluation
    disagreement_mean: float | None
    collect_seconds: float
    fit_seconds: float
    eval_seconds: float
    episode_faults: int = 0  # episodes of this round (collected and evaluated) that ended on a numerical fault
    planner_faults: int = 0  # plans of this round that met non-finite predictions or rewards (rejected)


@dataclass
class PhaseFaults:
    """The numerical faults of a round's collection or evaluation: its episodes' faults.log lines, and
    what the planner met (see motorlab.planning.mpc.PlannerFaults)."""

    log: list[str] = field(default_factory=list)
    episodes: int = 0  # episodes that ended on a numerical fault (one line each in `log`)
    planner: FaultCounts = FaultCounts()

    @classmethod
    def of(cls, result: MPCEpisodes, where: str, reward: str, model: str) -> PhaseFaults:
        """The faults of an MPC phase, its lines prefixed with `where` ("round 2 collect")."""
        log = [f"{where}: {line}" for line in result.fault_log]
        if result.planner.faulty_plans:
            log.append(f"{where}: {planner_fault_line(result.planner, reward, model, result.first_planner_fault)}")
        return cls(log, len(result.fault_log), result.planner)

    def __add__(self, other: PhaseFaults) -> PhaseFaults:
        return PhaseFaults(self.log + other.log, self.episodes + other.episodes, self.planner + other.planner)

    def to_json(self) -> dict[str, Any]:
        return {"log": self.log, "episodes": self.episodes, "planner": asdict(self.planner)}

    @classmethod
    def from_json(cls, d: dict[str, Any] | None) -> PhaseFaults:
        """What `to_json` wrote (nothing: no faults, as in folders written before faults were kept)."""
        d = d or {}
        return cls(list(d.get("log", [])), int(d.get("episodes", 0)), FaultCounts(**d.get("planner", {})))


@dataclass(frozen=True)
class LoopPlan:
    """What the loop runs: the env, the rounds, and the fit and planner settings it passes on."""

    env_id: str
    env: dict[str, Any]  # the env's settings besides its id (EnvConfig's, where not their defaults)
    rounds: int
    episodes_per_round: int
    eval_episodes: int
    collect_steps: int | None  # collected episodes end (truncated) after this many steps (None: the time limit)
    seed: int
    parallel: int
    holdout_every: int
    until_return: float | None
    until_every_episode: bool  # until_return on the worst evaluation episode, not the mean
    max_env_steps: int | None  # stop after the round whose collection reaches this many env steps
    state: str
    fit: dict[str, Any]  # fit_model's keyword arguments
    optimizer: str
    plan: dict[str, Any]  # the optimizer's settings
    scoring: dict[str, Any]  # build_policy's reward, termination, propagation, particles, device
    collect_noise: float = 0.0  # exploration noise on the collected episodes' actions (MPCPolicy's explore)
    eval_every: int = 1  # evaluate every Nth round and the last (the others' records carry no return)


def holdout(episodes: np.ndarray, every: int, per_round: int) -> np.ndarray:
    """The held-out ones of these episode numbers: every `every`-th, starting from the second (1, 1 +
    every, ...) where rounds collect several, so round 1 has one; with one episode a round, from the
    every-th (every - 1, 2 every - 1, ...), so the planner's first episodes are all trained on. None
    when every == 0."""
    if not every:
        return episodes[:0]
    return episodes[(episodes % every) == (1 % every if per_round > 1 else every - 1)]


def _round_dir(run_dir: Path, r: int) -> Path:
    return Path(run_dir) / "rounds" / f"{r:02d}"


def env_config(plan: LoopPlan) -> EnvConfig:
    """The env the loop collects from and plans in: its id and settings (wrappers, arguments)."""
    return EnvConfig.model_validate({"id": plan.env_id, **plan.env})


def collect_config(plan: LoopPlan) -> EnvConfig:
    """The env the loop collects from: env_config's, its episodes cut after collect_steps (Gymnasium's
    TimeLimit, through gymnasium.make's max_episode_steps: the episode ends as truncated)."""
    cfg = env_config(plan)
    if plan.collect_steps is None:
        return cfg
    limit = min(plan.collect_steps, cfg.kwargs.get("max_episode_steps", plan.collect_steps))
    return cfg.model_copy(update={"kwargs": {**cfg.kwargs, "max_episode_steps": limit}})


def _planner(plan: LoopPlan, model: ForwardModel, r: int, explore: float = 0.0):
    env = make_env(env_config(plan), shaped=False)
    try:
        return build_policy(env, env_config(plan), model, plan.optimizer, plan.seed * 1000 + r, **plan.scoring,
                            explore=explore, **plan.plan)
    finally:
        env.close()


COLLECT_FAULTS = "collect_faults"  # the key of a round's collection faults in its transitions' meta


def _collect(plan: LoopPlan, r: int, first_episode: int, model: ForwardModel | None,
             progress: bool) -> tuple[Transitions, PhaseFaults]:
    """Round r's episodes: random actions in round 1, else MPC on the last round's model."""
    base = plan.seed * SEED_STRIDE + first_episode
    n = plan.episodes_per_round
    if model is None:
        data = collect_transitions(collect_config(plan), n, "random", workers=1, seed=base, state=plan.state,
                                   progress=False)
        data.episode = data.episode + first_episode
        # the cut is how the loop collects, not the env the model learns: models and plans record the env
        data.meta["env"] = env_record(env_config(plan))
        return data, PhaseFaults([f"round {r + 1} collect: {line}" for line in data.meta["fault_log"]],
                                 data.meta["numerical_faults"])
    policy = _planner(plan, model, r, explore=plan.collect_noise)
    result = run_episodes(collect_config(plan), policy, n, base, min(plan.parallel, n), progress=progress,
                          seeds=[base + i for i in range(n)], record=True)
    faults = PhaseFaults.of(result, f"round {r + 1} collect", policy.task.reward_source, f"rounds/{r - 1:02d}/model")
    # an episode that ended on a numerical fault is left out whole (motorlab.dynamics.collection.whole_episodes)
    kept = [i for i, p in enumerate(result.paths) if i not in result.faulted
            and np.isfinite(p.observations).all() and np.isfinite(p.rewards).all()]
    if not kept:
        raise MotorlabError(f"round {r + 1}: every episode ended on a numerical fault "
                            f"({result.fault_log[0] if result.fault_log else 'non-finite observations'}).")
    arrays = episode_arrays(*zip(*[tuple(result.paths[i]) for i in kept]), layout=policy.layout,
                            episode_ids=[first_episode + i for i in kept])
    return Transitions(**arrays, meta={}), faults


def is_last_round(plan: LoopPlan, r: int, env_steps: int) -> bool:
    """Whether round r ends the loop whatever its evaluation says: the rounds' cap, or the env-step budget."""
    return r == plan.rounds - 1 or (plan.max_env_steps is not None and env_steps >= plan.max_env_steps)


def evaluates(plan: LoopPlan, r: int, env_steps: int) -> bool:
    """Whether round r is evaluated: every eval_every-th round, and always the last (its return is the loop's)."""
    return (r + 1) % plan.eval_every == 0 or is_last_round(plan, r, env_steps)


def _evaluate(plan: LoopPlan, model: ForwardModel, r: int, progress: bool) -> tuple[dict[str, float | None],
                                                                                   PhaseFaults]:
    if plan.eval_episodes == 0:
        return {"eval_return_mean": None, "eval_return_std": None, "eval_return_min": None, "plan_ms_median": None,
                "disagreement_mean": None}, PhaseFaults()
    policy = _planner(plan, model, r)
    base = plan.seed * SEED_STRIDE + EVAL_OFFSET
    result = run_episodes(env_config(plan), policy, plan.eval_episodes, base, min(plan.parallel, plan.eval_episodes),
                          progress=progress)
    return ({"eval_return_mean": float(result.returns.mean()), "eval_return_std": float(result.returns.std()),
             "eval_return_min": float(result.returns.min()),
             "plan_ms_median": float(np.median(result.per_env_ms)), "disagreement_mean": policy.disagreement_mean()},
            PhaseFaults.of(result, f"round {r + 1} eval", policy.task.reward_source, f"rounds/{r:02d}/model"))


def _held_out_mse(model: ForwardModel, data: Transitions, episodes: np.ndarray) -> float | None:
    rows = np.flatnonzero(np.isin(data.episode, episodes))
    if len(rows) == 0:
        return None
    x, y = model.training_pairs(data.states[rows], data.actions[rows], data.next_states[rows], data.rewards[rows])
    return evaluate_rows(model, x, y, torch.as_tensor(data.terminated[rows], dtype=torch.float32))["valid_mse"]


def check_resumable(run_dir: Path, plan: LoopPlan, resume: bool) -> None:
    """A loop folder holding rounds continues only with resume=True and the same settings (more rounds allowed)."""
    run_dir = Path(run_dir)
    started = (run_dir / LOOP_JSON).is_file()
    if started and not resume:
        raise MotorlabError(f"{run_dir} holds an earlier mbrl loop; pass --resume to continue it, or choose "
                            "another --out.")
    if resume and started:
        before = read_json(run_dir / LOOP_JSON)
        now, before = _flat(_comparable(asdict(plan))), _flat(before)
        changed = sorted(k for k in now.keys() | before.keys() if now.get(k) != before.get(k))
        if changed:
            raise MotorlabError(f"--resume continues {run_dir} with its own settings, but {', '.join(changed)} "
                                "differ; run it with the settings in its config.toml (only --rounds may grow).")


def _flat(settings: dict[str, Any]) -> dict[str, Any]:
    """Nested settings (fit, plan, scoring) as one level, under their own names."""
    flat = {}
    for k, v in settings.items():
        flat.update(v if isinstance(v, dict) else {k: v})
    return flat


# settings added after loop folders were first written (the loop's own, and fit_model's): at these
# values (what those loops ran with) they are left out of loop.json, so a folder written before them
# stays resumable
_ADDED_LATER = {"collect_noise": 0.0, "nll_beta": 0.0}
# what only sets which rounds are evaluated: a resumed loop may change it (no model depends on it)
_EVALUATION_ONLY = ("eval_every",)


def _without_later_defaults(settings: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in settings.items() if not (k in _ADDED_LATER and v == _ADDED_LATER[k])}


def _comparable(plan: dict[str, Any]) -> dict[str, Any]:
    """The settings a resumed loop must share with the interrupted one (JSON-shaped, rounds left out)."""
    import json

    left_out = ("rounds", "until_return", "until_every_episode", "max_env_steps", *_EVALUATION_ONLY)
    kept = _without_later_defaults({k: v for k, v in plan.items() if k not in left_out})
    return json.loads(json.dumps({**kept, "fit": _without_later_defaults(kept["fit"])}))


@dataclass
class LoopResult:
    records: list[RoundRecord]
    model: ForwardModel  # the last round's
    transitions: Transitions  # every round's
    task: Any  # the reward and termination the planner scored (motorlab.dynamics.planner_rewards.Task)
    faults: PhaseFaults = field(default_factory=PhaseFaults)  # every round's


def run_loop(plan: LoopPlan, run_dir: Path, progress: bool = True, resume: bool = False) -> LoopResult:
    """The loop, round by round, into `run_dir` (see the module's docstring)."""
    run_dir = Path(run_dir)
    check_resumable(run_dir, plan, resume)
    write_json(run_dir / LOOP_JSON, _comparable(asdict(plan)))
    records: list[RoundRecord] = []
    parts: list[Transitions] = []
    faults = PhaseFaults()
    meta: dict[str, Any] | None = None
    model: ForwardModel | None = None
    first_valid: np.ndarray | None = None
    curve = MetricsWriter(run_dir / CURVE, list(RoundRecord.__dataclass_fields__))
    columns = (TextColumn("mbrl {task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} rounds"),
               TextColumn("{task.fields[status]}"), TimeElapsedColumn())
    try:
        with Progress(*columns, disable=not progress) as bar:
            task = bar.add_task(plan.env_id, total=plan.rounds, status="")
            for r in range(plan.rounds):
                folder = _round_dir(run_dir, r)
                first_episode = r * plan.episodes_per_round
                # 1. collect (kept if this round's transitions were written before a kill)
                start = time.perf_counter()
                if (folder / TRANSITIONS).is_file():
                    data = load_transitions(folder / TRANSITIONS)
                    collected = PhaseFaults.from_json(data.meta.pop(COLLECT_FAULTS, None))
                else:
                    bar.update(task, status="collecting" if r else "collecting (random actions)")
                    data, collected = _collect(plan, r, first_episode, model, progress=False)
                    if meta is None:
                        meta = dict(data.meta, policy="random, then MPC on each round's model")
                    data.meta = {**meta, COLLECT_FAULTS: collected.to_json()}
                    data.save(folder / TRANSITIONS)
                    data.meta = meta
                meta = meta or data.meta
                collect_seconds = time.perf_counter() - start
                parts.append(data)
                everything = concatenate(parts, meta)
                valid = holdout(np.unique(everything.episode), plan.holdout_every, plan.episodes_per_round)
                if first_valid is None or not len(first_valid):  # the first round that holds one out
                    first_valid = holdout(np.unique(data.episode), plan.holdout_every, plan.episodes_per_round)
                # 2. refit on everything so far, warm-started from the last model
                start = time.perf_counter()
                if (folder / "model" / MODEL_JSON).is_file():
                    model = load_model(folder / "model")
                    fit_result = read_json(folder / "model" / MODEL_JSON).get("metrics", {})
                else:
                    bar.update(task, status=f"fitting on {len(everything):,} transitions")
                    model, fit_result = fit_model(everything, seed=plan.seed + r, init=model, valid_episodes=valid,
                                                  progress=False, **plan.fit)
                    fit_result.pop("history")
                    model.save(folder / "model", metrics=fit_result)
                fit_seconds = time.perf_counter() - start
                # 3. evaluate the planner on the new model
                start = time.perf_counter()
                if (folder / ROUND_JSON).is_file():
                    done = read_json(folder / ROUND_JSON)
                    record = RoundRecord(**{"eval_return_min": None, **done["record"]})  # older rounds lack it
                    round_faults = PhaseFaults.from_json(done.get("faults"))
                else:
                    bar.update(task, status="evaluating")
                    # the evaluation's planner and resets are seeded apart from collection's and the fit's, so
                    # evaluating fewer rounds changes no model, only the curve's points and the time they cost
                    numbers, evaluated = _evaluate(plan if evaluates(plan, r, len(everything)) else
                                                   replace(plan, eval_episodes=0), model, r, progress=False)
                    round_faults = collected + evaluated
                    record = RoundRecord(
                        round=r + 1, env_steps=len(everything), episodes=len(np.unique(everything.episode)),
                        collect_return_mean=float(np.bincount(data.episode - first_episode, weights=data.rewards)[
                            np.unique(data.episode - first_episode)].mean()),
                        valid_mse=fit_result.get("valid_mse"), valid_mse_first=_held_out_mse(model, everything,
                                                                                             first_valid),
                        collect_seconds=collect_seconds, fit_seconds=fit_seconds,
                        eval_seconds=time.perf_counter() - start, **numbers,
                        episode_faults=round_faults.episodes,
                        planner_faults=round_faults.planner.faulty_plans)
                    write_json(folder / ROUND_JSON, {
                        "record": asdict(record), "faults": round_faults.to_json(),
                        "collected_with": "random actions" if r == 0 else {
                            "model": f"rounds/{r - 1:02d}/model", "optimizer": plan.optimizer, **plan.plan,
                            **plan.scoring, "seed": plan.seed * 1000 + r,  # _collect's planner's
                            **({"explore": plan.collect_noise} if plan.collect_noise else {})},
                        "evaluated_with": {"model": f"rounds/{r:02d}/model", "optimizer": plan.optimizer, **plan.plan,
                                           **plan.scoring, "seed": plan.seed * 1000 + r,
                                           "episodes": plan.eval_episodes},
                        "fit": {k: (list(v) if isinstance(v, tuple) else v) for k, v in plan.fit.items()},
                        "held_out_episodes": valid.tolist()})
                records.append(record)
                faults = faults + round_faults
                curve.write(asdict(record))
                # the tracked run (--track), live: curve.csv's row, against the env steps collected so far
                trackers.scalars({f"round/{k}": v for k, v in asdict(record).items() if k != "env_steps"},
                                 record.env_steps)
                shown = f"return {record.eval_return_mean:.1f}" if record.eval_return_mean is not None else ""
                bar.update(task, advance=1, status=f"{record.env_steps:,} steps, {shown}")
                if reached(record, plan.until_return, plan.until_every_episode):
                    break
                if is_last_round(plan, r, record.env_steps):
                    break
    finally:
        curve.close()
    return LoopResult(records, model, concatenate(parts, meta), _planner(plan, model, len(records)).task, faults)


def reached(record: RoundRecord, target: float | None, every_episode: bool = False) -> bool:
    """Whether a round's evaluation reached `target`: its mean return, or with `every_episode` its worst
    episode's (False without a target or an evaluation)."""
    value = record.eval_return_min if every_episode else record.eval_return_mean
    return target is not None and value is not None and value >= target


def layout_name(env: str | EnvConfig, state: str) -> str:
    """The state layout the loop's transitions use (checked against the env: an id, or an EnvConfig
    with its wrappers), after refusing an env the planner cannot act on (one line, before any folder
    is touched)."""
    cfg = env if isinstance(env, EnvConfig) else EnvConfig(id=env)
    env_id = cfg.id
    env = make_env(cfg, shaped=False)
    try:
        require_plannable(env, env_id, "mbrl (MPC on a learned model)")
        return env_layout(env, env_id, state).name
    finally:
        env.close()
