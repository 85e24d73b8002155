"""Measure robustness curves: every policy, every grid value of every axis, `episodes` episodes each
from the same reset seeds, so that at each value all policies face the same initial states."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rich.progress import Progress

from motorlab.envs import EnvConfig, early_end_label, given_env, make_env, max_return
from motorlab.envs.catalog import facts
from motorlab.errors import MotorlabError
from motorlab.evaluation.rollouts import evaluate, step_success, trained_env_settings
from motorlab.evaluation.zeroshot import run_label
from motorlab.policies import BUILTIN_POLICIES, load_policy, unknown_policy_message
from motorlab.robustness_curves.grid import Axis
from motorlab.runs import atomic_write_text, require_run_dir

HOLDS = 0.9  # a policy holds at a grid value while at least 90% of its episodes succeed (or do not fall)


@dataclass(frozen=True)
class Subject:
    """One policy under test: a run folder (one seed of a step) or a built-in controller."""

    spec: str
    label: str  # "ppo", "ppo/seed1", "pid"
    env: EnvConfig  # the env it acts in before any disturbance of the grid

    @property
    def group(self) -> str:
        """The curve it belongs to: seeds of one step share one line."""
        return self.label.split("/")[0]


@dataclass
class Point:
    """One policy at one grid value: per-episode numbers."""

    label: str
    group: str
    key: str
    value: float
    returns: np.ndarray
    lengths: np.ndarray
    success: np.ndarray
    falls: int
    faults: list[str] = field(default_factory=list)


@dataclass
class Curves:
    """Every point, and how to read success for this env."""

    axes: list[Axis]
    groups: list[str]
    points: list[Point]
    measure: str  # "success", "no fall" or "return": what "holds" is judged on
    episodes: int

    def at(self, group: str, key: str) -> list[list[Point]]:
        """The points of one curve, grid value by grid value, each with one point per seed."""
        axis = next(a for a in self.axes if a.key == key)
        return [[p for p in self.points if p.group == group and p.key == key and p.value == v] for v in axis.values]

    def rate(self, points: list[Point]) -> float:
        """The fraction of episodes that hold: succeed, or do not fall."""
        if self.measure == "success":
            return float(np.mean(np.concatenate([p.success for p in points])))
        n = sum(len(p.returns) for p in points)
        return 1.0 - sum(p.falls for p in points) / n

    def holds(self, group: str, key: str) -> tuple[float, float] | None:
        """The widest run of consecutive grid values over which the policy holds (None: at none).

        A policy trained under a delay may fail without it and hold around it, so this is a band,
        not "up to": (low, high), the first of the widest runs. Holding is >= 90% of episodes
        succeeding (or not falling); with the "return" measure, a mean return within 10% of the
        policy's best on the grid."""
        values = next(a for a in self.axes if a.key == key).values
        rows = self.at(group, key)
        if self.measure == "return":
            means = [float(np.mean(np.concatenate([p.returns for p in pts]))) for pts in rows]
            best = max(means)
            ok = [m >= best - (1 - HOLDS) * abs(best) for m in means]
        else:
            ok = [self.rate(pts) >= HOLDS for pts in rows]
        best_run: tuple[int, int] | None = None
        start = None
        for i, good in enumerate([*ok, False]):
            if good and start is None:
                start = i
            elif not good and start is not None:
                if best_run is None or i - 1 - start > best_run[1] - best_run[0]:
                    best_run = (start, i - 1)
                start = None
        return None if best_run is None else (values[best_run[0]], values[best_run[1]])

    def curve(self, group: str, key: str) -> dict[str, list]:
        """A curve as numbers: per grid value the mean return, its quartiles over episodes and seeds,
        and the rate that holds."""
        rows = self.at(group, key)
        returns = [np.concatenate([p.returns for p in pts]) for pts in rows]
        out = {
            "values": list(next(a for a in self.axes if a.key == key).values),
            "return_mean": [float(np.mean(r)) for r in returns],
            "return_q25": [float(np.percentile(r, 25)) for r in returns],
            "return_q75": [float(np.percentile(r, 75)) for r in returns],
            "seeds": len(rows[0]),
        }
        if self.measure != "return":  # "success_rate" or "no_fall_rate"
            out[f"{self.measure.replace(' ', '_')}_rate"] = [self.rate(pts) for pts in rows]
        return out


# What a run folder's env settings say about the policy itself, kept under test: the env, its
# arguments, the observation history and the synergy space it acts in. How it was trained (delay,
# latency, noise, pushes, randomized ranges) is not the plant under test: every policy meets the
# same env at each grid value, the robustness step's own settings plus the grid's disturbance.
STRUCTURE = ("id", "history", "sar", "phi", "kwargs", "success")


def subjects(policies: list[str], env: EnvConfig | dict[str, Any]) -> list[Subject]:
    """The policies as run folders (their env's STRUCTURE, under the settings `env` was given) or
    built-in controllers (in `env`, whose id defaults to the first run's). What `env` was not
    given (EnvConfig.model_fields_set; a dict: its keys) is each run's own, or the default.

    Raises:
        MotorlabError: a policy that is neither; no env id for a built-in controller.
    """
    env = given_env(env if isinstance(env, EnvConfig) else EnvConfig.model_validate(env))
    found: list[tuple[str, Path | None]] = []
    for spec in policies:
        if Path(spec).exists():
            found.append((spec, require_run_dir(Path(spec))))
        elif spec.split(":", 1)[0] in BUILTIN_POLICIES:
            found.append((spec, None))
        else:
            raise MotorlabError(unknown_policy_message(spec))
    runs = [run for _, run in found if run is not None]
    default_id = env.get("id") or (trained_env_settings(runs[0]).get("id") if runs else None)
    out = []
    for spec, run in found:
        if run is None:
            if default_id is None:
                raise MotorlabError(f"no env for {spec!r}: give --env ENV_ID (e.g. --env InvertedPendulum-v5).")
            out.append(Subject(spec, spec, EnvConfig.model_validate({**env, "id": default_id})))
        else:
            own = {k: v for k, v in trained_env_settings(run).items() if k in STRUCTURE}
            kwargs = {**own.get("kwargs", {}), **env.get("kwargs", {})}
            out.append(Subject(str(run), run_label(run), EnvConfig.model_validate({**own, **env, "kwargs": kwargs})))
    labels = [s.label for s in out]
    if len(set(labels)) < len(labels):
        out = [Subject(s.spec, s.spec, s.env) for s in out]
    return out


def success_measure(env_id: str, cfg: EnvConfig) -> str:
    """What "holds" is judged on: the env's success flag or maximum return where it has one, else
    not falling where early ends are falls, else the return itself."""
    env = make_env(cfg, shaped=False)
    try:
        env.reset(seed=0)
        flagged = step_success(env.step(env.action_space.sample())[4], facts(env_id).success_keys) is not None
    finally:
        env.close()
    if flagged or max_return(env_id) is not None:
        return "success"
    return "no fall" if early_end_label(env_id) == "falls" else "return"


def measure(targets: list[Subject], axes: list[Axis], episodes: int, seed: int, workers: int | None = None,
            progress: bool = True) -> Curves:
    """Evaluate every policy at every grid value of every axis (the other axes at the policy's own
    settings), episode i of every point from reset seed `seed + i`."""
    configs = {s.label: s.env for s in targets}
    for axis in axes:  # a bad combination fails before the first episode: e.g. pushes without a body
        probe = {**configs[targets[0].label].model_dump(), axis.key: axis.env_value(axis.values[-1])}
        if axis.key == "push_force" and not probe["push_body"]:
            raise MotorlabError("--vary push-force needs the body to push: give --push-body BODY (e.g. pole).")
        make_env(EnvConfig.model_validate(probe), shaped=False).close()
    first = configs[targets[0].label]
    kind = success_measure(first.id, first)
    points: list[Point] = []
    total = len(targets) * sum(len(a.values) for a in axes)
    with Progress(disable=not progress, transient=False) as bar:
        task = bar.add_task("evaluating", total=total)
        for s in targets:
            base = configs[s.label]
            probe = make_env(base, shaped=False)
            try:
                policy = load_policy(s.spec, probe, base.id, seed)
            finally:
                probe.close()
            for axis in axes:
                for value in axis.values:
                    bar.update(task, description=f"{s.label}: {axis.key.replace('_', '-')} {value:g}")
                    cfg = EnvConfig.model_validate({**base.model_dump(), axis.key: axis.env_value(value)})
                    r = evaluate(policy, cfg, episodes, seed, workers=workers)
                    points.append(Point(s.label, s.group, axis.key, value, r.returns, r.lengths, r.success, r.falls,
                                        [f"{s.label} at {axis.key}={value:g}: {line}" for line in r.fault_log]))
                    bar.advance(task)
    groups = list(dict.fromkeys(s.group for s in targets))
    return Curves(axes, groups, points, kind, episodes)


def write_points_csv(path: Path, curves: Curves) -> None:
    """curves.csv: one row per episode (policy, seed run, disturbance, value, return, length, success); the
    success cell is empty where the env defines no success (no flag, no maximum return): not a 0."""
    defined = curves.measure == "success"
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["policy", "run", "disturbance", "value", "episode", "return", "length", "success"])
    for p in curves.points:
        for i, (ret, length, ok) in enumerate(zip(p.returns, p.lengths, p.success, strict=True)):
            w.writerow([p.group, p.label, p.key, f"{p.value:g}", i, f"{ret:.6g}", int(length),
                        int(ok) if defined else ""])
    atomic_write_text(path, buf.getvalue())

