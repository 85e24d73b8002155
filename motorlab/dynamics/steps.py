"""The forward-model step kinds: `dynamics-collect` transitions, `dynamics-fit` a forward model,
`dynamics-check` it against the simulator open loop."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator
from rich.console import Console

from motorlab.dynamics.state import xy_columns
from motorlab.dynamics.transitions import TRANSITIONS, load_transitions
from motorlab.envs import check_env_id
from motorlab.report.results import Metric, Number
from motorlab.runs import atomic_write_npz
from motorlab.settings import Settings, Summary
from motorlab.stepkind import Artifact, Ref, StepKind

# ---- dynamics-collect -------------------------------------------------------------------------


class DynamicsCollectSettings(Settings):
    env: str = Field(description="Gymnasium env id, e.g. Reacher-v5")
    episodes: int = Field(1000, gt=0, description="Episodes to run, each to its end")
    policy: str = Field("random", description="random (uniform actions) or a run folder from `motorlab train`")
    workers: int | None = Field(None, gt=0, description="Processes or threads (default: all cores)")
    state: Literal["auto", "reacher", "observation"] = Field(
        "auto", description="State layout: auto (Reacher: cos, sin, joint velocities, fingertip x-y; else the "
        "observation), reacher, observation")
    simulator: Literal["auto", "closed-form", "mujoco", "gymnasium"] = Field(
        "auto", description="auto (Reacher with random actions: closed-form where the arm's closed-form dynamics "
        "reproduce MuJoCo's, else mujoco; any other env or policy: gymnasium); closed-form (the arm's equations "
        "of motion in NumPy, all episodes at once, equal to MuJoCo's to its solver tolerance); mujoco "
        "(mujoco.rollout in C on every core, bit for bit Gymnasium's joints); gymnasium (the env itself, in a "
        "process pool)")
    seed: int = Field(0, ge=0, description="Random seed (initial states and actions)")


class DynamicsCollectSummary(Summary):
    env_id: str
    transitions: int
    episodes: int
    transitions_per_second: float
    collect_seconds: float
    simulator: str
    state_layout: str
    state_size: int
    action_size: int
    return_mean: float
    numerical_faults: int


class DynamicsCollectKind(StepKind[DynamicsCollectSettings, DynamicsCollectSummary]):
    """Record transitions (state, action, next state, reward, done) to transitions.npz."""

    name = "dynamics-collect"
    what = "collect {episodes:,} {policy} episodes of {env}"
    headline_keys = ("transitions", "transitions_per_second", "simulator", "collect_seconds")
    metrics = (Metric("transitions", "transitions", "count"),
               Metric("transitions_per_second", "transitions per second", "count"),
               Metric("simulator", "simulator", "text", setup=True),
               Metric("collect_seconds", "collection time", "s", setup=True))
    refs = (Ref("policy", ("policy",)),)
    provides = Artifact("transitions", TRANSITIONS)

    def check(self, settings: DynamicsCollectSettings) -> None:
        check_env_id(settings.env)

    def run(self, settings: DynamicsCollectSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DynamicsCollectSummary:
        from motorlab.dynamics.collect import collect_transitions

        s = settings
        data = collect_transitions(s.env, s.episodes, s.policy, s.workers, s.seed, s.state, s.simulator, progress)
        run_dir = self.start(out)
        data.save(run_dir / TRANSITIONS)
        seconds = data.meta["seconds"]
        summary = DynamicsCollectSummary(
            env_id=s.env, transitions=len(data), episodes=s.episodes, transitions_per_second=len(data) / seconds,
            collect_seconds=seconds, simulator=data.meta["simulator"], state_layout=data.meta["state_layout"],
            state_size=data.states.shape[1], action_size=data.actions.shape[1],
            return_mean=float(np.bincount(data.episode, weights=data.rewards)[np.unique(data.episode)].mean()),
            numerical_faults=data.meta["numerical_faults"])
        return self.finish(run_dir, settings, summary, data.meta["fault_log"])


DYNAMICS_COLLECT = DynamicsCollectKind()


# ---- dynamics-fit -----------------------------------------------------------------------------


class DynamicsFitSettings(Settings):
    transitions: str = Field(description="transitions.npz (or its folder) from `dynamics collect`")
    epochs: int = Field(50, gt=0, description="Passes over the training data (the most, with --patience)")
    hidden: list[int] = Field(default_factory=lambda: [64, 64], min_length=1,
                              description="Hidden layer widths (Tanh + LayerNorm each)")
    ensemble: int = Field(1, gt=0, description="Members K, trained together as one batched net")
    lr: float = Field(2e-3, gt=0, description="Adam's learning rate, cosine-decayed to 0")
    batch_size: int = Field(2000, gt=0, description="Rows per gradient step")
    valid_fraction: float = Field(0.1, ge=0, lt=1, description="Share of episodes held out for valid_mse")
    patience: int | None = Field(None, gt=0, description="Early stopping: epochs without a better valid_mse")
    seed: int = Field(0, ge=0, description="Random seed (initialization, batch order, validation split)")

    @model_validator(mode="after")
    def _usable(self):
        # fit_model's own check, run here once, so bad settings fail before a run folder is touched
        from motorlab.dynamics.train import check_settings

        check_settings(self.epochs, tuple(self.hidden), self.ensemble, self.lr, self.batch_size, self.valid_fraction,
                       self.patience)
        return self


class DynamicsFitSummary(Summary):
    env_id: str
    state_layout: str | None
    valid_mse: float | None
    train_mse: float
    epochs_run: int
    best_epoch: int
    train_rows: int
    valid_rows: int
    train_seconds: float
    wall_seconds: float
    transitions: int
    members: int
    hidden: list[int]


class DynamicsFitKind(StepKind[DynamicsFitSettings, DynamicsFitSummary]):
    """Fit a forward model predicting the normalized state delta; writes model.safetensors + model.json."""

    name = "dynamics-fit"
    what = "fit a forward model {ensemble}x{hidden} to {transitions}"
    note = "MSE of the normalized state change on held-out transitions"
    headline_keys = ("valid_mse", "epochs_run", "wall_seconds", "train_rows")
    metrics = (Metric("valid_mse", "valid MSE"),
               Metric("epochs_run", "epochs", "count", setup=True),
               Metric("train_rows", "training rows", "count", setup=True),
               Metric("wall_seconds", "training time", "s", setup=True))
    refs = (Ref("transitions", ("transitions",)),)
    provides = Artifact("model")

    def run(self, settings: DynamicsFitSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DynamicsFitSummary:
        from motorlab.dynamics.train import fit_model
        from motorlab.report.dynamics_plots import loss_curve

        s = settings
        start = time.perf_counter()
        data = load_transitions(Path(s.transitions))
        run_dir = self.start(out)
        model, result = fit_model(data, s.epochs, tuple(s.hidden), s.ensemble, s.lr, s.batch_size, s.valid_fraction,
                                  s.patience, s.seed, run_dir=run_dir, progress=progress, checked=True)
        history = result.pop("history")
        loss_curve(history, run_dir / "plots" / "loss.png",
                   f"{data.env_id}: forward model ({model.members}x{list(s.hidden)})")
        summary = DynamicsFitSummary(env_id=data.env_id, state_layout=data.meta.get("state_layout"), **result,
                                     wall_seconds=time.perf_counter() - start, transitions=len(data),
                                     members=model.members, hidden=list(s.hidden))
        model.save(run_dir, metrics={k: v for k, v in summary.keys().items() if k not in ("env_id", "state_layout")})
        return self.finish(run_dir, settings, summary)


DYNAMICS_FIT = DynamicsFitKind()


# ---- dynamics-check ---------------------------------------------------------------------------


class DynamicsCheckSettings(Settings):
    model: str = Field(description="A model folder from `dynamics fit`")
    episodes: int = Field(5, gt=0, description="Open-loop episodes (random actions)")
    steps: int | None = Field(None, gt=0, description="Steps per episode (default: the env's time limit)")
    seed: int = Field(0, ge=0, description="Random seed (initial states and actions)")


class DynamicsCheckSummary(Summary):
    """Also state_nrmse_h<k> for k in 1, 5, 10, 25 and _final, and for layouts with a fingertip
    tip_error_mean_h<k> and tip_error_mean_final."""

    env_id: str
    episodes: int
    horizon: int


class DynamicsCheckKind(StepKind[DynamicsCheckSettings, DynamicsCheckSummary]):
    """Model vs simulator under the same actions, open loop: error vs horizon, x-y traces, summary numbers."""

    name = "dynamics-check"
    what = "check {model} open loop, {episodes} episodes"
    key_figures = ("plots/tip_error.png", "plots/traces.png")
    refs = (Ref("model", ("model",)),)

    def run(self, settings: DynamicsCheckSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DynamicsCheckSummary:
        from motorlab.dynamics.check import REPORT_STEPS, open_loop
        from motorlab.dynamics.model import load_model
        from motorlab.report.dynamics_plots import error_vs_horizon, xy_traces

        model = load_model(Path(settings.model))
        r = open_loop(model, settings.episodes, settings.seed, settings.steps)
        run_dir = self.start(out)
        env_id = model.meta["env_id"]
        labels = list(model.meta.get("state_labels") or [])
        scale = model.state_norm.std.numpy()  # state errors in units of each entry's spread in the data
        diff = r["model"] - r["true"]
        nrmse = np.sqrt(((diff / scale) ** 2).mean(-1))  # (E, T+1)
        last = diff.shape[1] - 1
        keys: dict[str, float] = {}
        xy = xy_columns(labels)
        if xy:
            tip = np.linalg.norm(diff[..., xy], axis=-1)
            keys.update({f"tip_error_mean_h{h}": float(tip[:, h].mean()) for h in REPORT_STEPS if h <= last})
            keys["tip_error_mean_final"] = float(tip[:, -1].mean())
            error_vs_horizon(np.arange(last + 1), {"fingertip": tip * 1000}, run_dir / "plots" / "tip_error.png",
                             f"{env_id}: open-loop fingertip error", "fingertip error (mm)")
        keys.update({f"state_nrmse_h{h}": float(nrmse[:, h].mean()) for h in REPORT_STEPS if h <= last})
        keys["state_nrmse_final"] = float(nrmse[:, -1].mean())
        error_vs_horizon(np.arange(last + 1), {"state (normalized RMSE)": nrmse},
                         run_dir / "plots" / "error_vs_horizon.png", f"{env_id}: model vs simulator, open loop",
                         "normalized RMSE")
        cols = xy or [0, 1]
        names = tuple(labels[c] if labels else f"state[{c}]" for c in cols)
        xy_traces(r["true"][..., cols], r["model"][..., cols], r["goals"] if xy else None,
                  run_dir / "plots" / "traces.png", f"{env_id}: simulator vs model, {settings.episodes} episodes",
                  tuple(n + (" (m)" if xy else "") for n in names))
        atomic_write_npz(run_dir / "rollouts.npz", **r)
        summary = DynamicsCheckSummary(env_id=env_id, episodes=settings.episodes, horizon=last, **keys)
        return self.finish(run_dir, settings, summary)

    def headline(self, s: DynamicsCheckSummary) -> dict[str, Any]:
        return {k: v for k, v in s.keys().items() if k.startswith(("tip_error_mean_", "state_nrmse_"))}

    def metric(self, key: str) -> Metric:
        horizon = key.rsplit("_", 1)[-1].removeprefix("h")  # "h10" -> "10", "final"
        where = "at the last step" if horizon == "final" else f"after {horizon} step{'s' * (horizon != '1')}"
        if key.startswith("tip_error_mean_"):
            return Metric(key, f"fingertip error {where}", "mm", scale=1000)
        if key.startswith("state_nrmse_"):
            return Metric(key, f"state NRMSE {where}")
        return super().metric(key)

    def numbers(self, settings: DynamicsCheckSettings, h: dict[str, Any]) -> list[Number]:
        """The open-loop fingertip error where the state has a fingertip, else the state's NRMSE."""
        tips = [k for k in h if k.startswith("tip_error_mean_")]
        return [n for k in (tips or [k for k in h if k.startswith("state_nrmse_")]) if (n := self.metric(k).number(h))]


DYNAMICS_CHECK = DynamicsCheckKind()
