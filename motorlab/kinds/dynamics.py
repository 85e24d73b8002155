"""The forward-model step kinds: `dynamics-collect` transitions, `dynamics-fit` a forward model,
`dynamics-check` it against the simulator open loop."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from pydantic import AfterValidator, Field, model_validator
from rich.console import Console

from motorlab.dynamics.layouts import about as layouts_about
from motorlab.dynamics.layouts import check_name, reached_of, reaching
from motorlab.dynamics.transitions import TRANSITIONS, load_transitions
from motorlab.envs import ENV_KEYS, EnvConfig, EnvSettings, check_env_id, describe_env
from motorlab.envs.spaces import decode_space, require_actions
from motorlab.errors import MotorlabError
from motorlab.report.results import Metric, Number
from motorlab.runs import atomic_write_npz
from motorlab.settings import MAX_SEED, Settings, Summary
from motorlab.stepkind import Artifact, Ref, StepKind, warn_faults

# ---- dynamics-collect -------------------------------------------------------------------------


def with_env(what: str, settings: EnvSettings) -> str:
    """A kind's "what" cell (a format of its settings) with the env in a few words: its id and the
    wrappers it was given ("Reacher-v5, history 3")."""
    return what.format(**{**settings.model_dump(), "env": describe_env(settings.env)})


# a layout is one file in motorlab.dynamics.layouts: the names and --help come from there
StateLayoutName = Annotated[str, AfterValidator(check_name)]


def state_field() -> Any:
    return Field("auto", description="State layout: auto (the env's catalogue entry's: Reacher's 8 numbers; else "
                 f"the observation); {layouts_about()}")


class DynamicsCollectSettings(EnvSettings):
    """The env as every env-building kind takes it (EnvConfig: id, delay, history, noise, ...,
    flat on the command line and in recipes): the transitions are what that env gives."""

    aliases: ClassVar[frozenset[str]] = frozenset(ENV_KEYS) - {"success"}
    env_refused: ClassVar[dict[str, str]] = {
        "success": "dynamics collect counts no successes (it records transitions); drop it."}
    env: EnvConfig = Field(description="The env to collect from: its id (e.g. Reacher-v5) and motorlab's "
                           "wrappers, given flat (--delay, --history, ...)")
    episodes: int = Field(1000, gt=0, description="Episodes to run, each to its end")
    policy: str = Field("random", description="random (random actions, colored by --noise-beta) or a run folder "
                        "from `motorlab train`")
    workers: int | None = Field(None, gt=0, description="Processes or threads (default: all cores)")
    state: StateLayoutName = state_field()
    simulator: Literal["auto", "closed-form", "mujoco", "gymnasium"] = Field(
        "auto", description="auto (Reacher with random actions and no env settings besides its id: closed-form "
        "where the arm's closed-form dynamics reproduce MuJoCo's, else mujoco; any other env, env settings or "
        "policy: gymnasium); closed-form (the arm's equations "
        "of motion in NumPy, all episodes at once, equal to MuJoCo's to its solver tolerance); mujoco "
        "(mujoco.rollout in C on every core, bit for bit Gymnasium's joints); gymnasium (the env itself, in a "
        "process pool)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (initial states and actions)")
    # pink by default: on generated arms (benchmarks/mbrl_bodies.py, development bodies 0-7, a fit of
    # [200, 200] units) pink random actions took the one-shot path from 0.74 to 0.90 of the random-to-
    # oracle gap with the user's reward and from 0.45 to 0.72 with the learned one (medians); white noise
    # jitters a body in place, pink sweeps it across its workspace (benchmarks/devlog/mbrl_bodies.jsonl)
    noise_beta: float = Field(1.0, ge=0, description="Color of the random actions along time, each spread over its "
                              "bounds: 0 white (independent uniform draws), 1 pink (the default), 2 red (slow "
                              "sweeps that carry a body across its workspace)")

    @model_validator(mode="after")
    def _color_only_random_actions(self):
        # a changed color with a trained policy is a mistake; the default is just unused (a saved config.toml
        # holds it, and must read back)
        default = type(self).model_fields["noise_beta"].default
        if self.policy != "random" and self.noise_beta != default:
            raise MotorlabError("--noise-beta colors random actions; a --policy run folder chooses its own: drop one.")
        return self

    def random_noise_beta(self) -> float:
        """The color collect_transitions gets: this one for random actions, none for a trained policy."""
        return self.noise_beta if self.policy == "random" else 0.0


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
    refs = (Ref("policy", ("policy",)), Ref("sar", ("sar",)))  # sar = "@fit": act in a fit step's synergies
    provides = Artifact("transitions", TRANSITIONS)
    arguments = ("env",)
    examples = ("motorlab dynamics collect Reacher-v5 --episodes 20000 --out runs/reacher-data",
                "motorlab dynamics collect InvertedPendulum-v5 --episodes 200 --policy runs/ppo")

    def check(self, settings: DynamicsCollectSettings) -> None:
        check_env_id(settings.env.id)

    def describe(self, settings: DynamicsCollectSettings, copies: int = 1) -> str:
        return with_env(self.what, settings)

    def run(self, settings: DynamicsCollectSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DynamicsCollectSummary:
        from motorlab.dynamics.collection import collect_transitions

        s = settings
        data = collect_transitions(s.env, s.episodes, s.policy, s.workers, s.seed, s.state, s.simulator, progress,
                                   before_work=lambda: self.refuse_finished_out(out), noise_beta=s.random_noise_beta())
        run_dir = self.start(out)
        data.save(run_dir / TRANSITIONS)
        seconds = data.meta["seconds"]
        summary = DynamicsCollectSummary(
            env_id=s.env.id, transitions=len(data), episodes=s.episodes, transitions_per_second=len(data) / seconds,
            collect_seconds=seconds, simulator=data.meta["simulator"], state_layout=data.meta["state_layout"],
            state_size=data.states.shape[1], action_size=data.actions.shape[1],
            return_mean=float(np.bincount(data.episode, weights=data.rewards)[np.unique(data.episode)].mean()),
            numerical_faults=data.meta["numerical_faults"])
        return self.finish(run_dir, settings, summary, data.meta["fault_log"])

    def report(self, s: DynamicsCollectSummary, settings: DynamicsCollectSettings, console: Console) -> None:
        console.print(f"{s.transitions:,} transitions ({s.state_size} state, {s.action_size} action entries) "
                      f"at {s.transitions_per_second:,.0f}/s via {s.simulator} -> {s.run_dir}/transitions.npz")
        warn_faults(s)


DYNAMICS_COLLECT = DynamicsCollectKind()


# ---- dynamics-fit -----------------------------------------------------------------------------


class ModelSettings(Settings):
    """How a forward model is built and trained: `dynamics fit` and the `mbrl` loop share these."""

    epochs: int = Field(50, gt=0, description="Passes over the training data (the most, with --patience)")
    hidden: list[int] = Field(default_factory=lambda: [64, 64], min_length=1,
                              description="Hidden layer widths")
    # silu: measured better than the reference notebook's tanh + LayerNorm with little data (the loop
    # on Reacher) and as good with plenty (motorlab.dynamics.model's docstring has the numbers)
    nonlinearity: Literal["silu", "tanh"] = Field("silu", description="The hidden layers': silu (SiLU, PETS' and "
                                                  "mbrl-lib's) or tanh (Tanh + LayerNorm, the reference "
                                                  "notebook's)")
    ensemble: int = Field(1, gt=0, description="Members K, trained together as one batched net")
    probabilistic: bool = Field(False, description="Gaussian members trained by negative log-likelihood, with "
                                "learned bounds on their variance (PETS), instead of deterministic ones")
    learn_reward: bool = Field(False, description="Also fit a reward head, for planning with --reward learned")
    learn_termination: bool = Field(False, description="Also fit a termination classifier, for planning with "
                                    "--termination learned")
    # PETS' plain NLL lets a probabilistic member call rare, sharp changes noise and stop fitting them:
    # on Pusher the loop's members explained none of the object's motion (R^2 ~0 on the rows where the
    # tip pushes it), so its plans pushed the object anywhere (motorlab/envs/catalog.py has the numbers)
    nll_beta: float = Field(0.0, ge=0, le=1, description="Probabilistic members: weigh each entry's negative "
                            "log-likelihood by its predicted variance ** beta (beta-NLL, Seitzer et al. 2022), so "
                            "what they call noisy still trains their mean; 0: PETS' plain NLL, 0.5: the paper's "
                            "advice")
    lr: float = Field(2e-3, gt=0, description="Adam's learning rate, cosine-decayed to 0")
    batch_size: int = Field(2000, gt=0, description="Rows per gradient step")
    valid_fraction: float = Field(0.1, ge=0, lt=1, description="Share of episodes held out for valid_mse")
    patience: int | None = Field(None, gt=0, description="Early stopping: epochs without a better valid_mse")
    keep_weights: Literal["best", "last"] = Field(
        "best", description="The weights the fit keeps: best (the epoch with the lowest valid_mse) or last (the "
        "final epoch's; valid_mse is still reported)")
    device: str = Field("auto", description="Where the model trains (and plans): auto (a GPU where torch sees "
                        "one, else the CPU), cpu, cuda, cuda:N")

    @model_validator(mode="after")
    def _usable(self):
        # fit_model's own check, run here once, so bad settings fail before a run folder is touched
        from motorlab.dynamics.train import check_settings

        check_settings(self.epochs, tuple(self.hidden), self.ensemble, self.lr, self.batch_size, self.valid_fraction,
                       self.patience, self.nll_beta)
        return self

    def heads(self) -> tuple[str, ...]:
        return tuple(h for h, on in (("reward", self.learn_reward), ("termination", self.learn_termination)) if on)

    def fit_args(self) -> dict[str, Any]:
        """fit_model's keyword arguments for these settings."""
        return dict(epochs=self.epochs, hidden=tuple(self.hidden), nonlinearity=self.nonlinearity,
                    ensemble=self.ensemble, lr=self.lr,
                    batch_size=self.batch_size, valid_fraction=self.valid_fraction, patience=self.patience,
                    keep_weights=self.keep_weights,
                    probabilistic=self.probabilistic, heads=self.heads(), device=self.device, checked=True,
                    nll_beta=self.nll_beta)


class DynamicsFitSettings(ModelSettings):
    transitions: str = Field(description="transitions.npz (or its folder) from `dynamics collect`")
    # [200, 200] (PETS' and mbrl-lib's width): on the generated arms' 40,000 transitions [64, 64] left the
    # one-shot path at 0.42 of the gap (median, user's reward) where [200, 200] reached 0.90 with pink
    # collection ([128, 128]: 0.74); the loop keeps its own [64, 64] (it refits every round)
    hidden: list[int] = Field(default_factory=lambda: [200, 200], min_length=1, description="Hidden layer widths")
    epochs: int | None = Field(None, gt=0, description="Passes over the training data (the most, with --patience); "
                               "default: 50, or more (up to 500) where the data is small, so the fit takes at "
                               "least 4,000 gradient steps")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (initialization, batch order, validation split)")


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
    probabilistic: bool = False
    heads: list[str] = []
    valid_nll: float | None = None
    valid_reward_mse: float | None = None
    valid_termination_accuracy: float | None = None


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
    arguments = ("transitions",)
    examples = ("motorlab dynamics fit runs/reacher-data --out runs/reacher-model",
                "motorlab dynamics fit runs/reacher-data/transitions.npz --hidden 128,128 --ensemble 5 --patience 5")

    def run(self, settings: DynamicsFitSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DynamicsFitSummary:
        from motorlab.dynamics.train import fit_model
        from motorlab.report.dynamics_plots import loss_curve

        s = settings
        start = time.perf_counter()
        data = load_transitions(Path(s.transitions))
        require_box_actions(data.meta, str(s.transitions))
        run_dir = self.start(out)
        model, result = fit_model(data, seed=s.seed, run_dir=run_dir, progress=progress, **s.fit_args())
        history = result.pop("history")
        loss_curve(history, run_dir / "plots" / "loss.png",
                   f"{data.env_id}: forward model ({model.members}x{list(s.hidden)})")
        summary = DynamicsFitSummary(env_id=data.env_id, state_layout=data.meta.get("state_layout"), **result,
                                     wall_seconds=time.perf_counter() - start, transitions=len(data),
                                     members=model.members, hidden=list(s.hidden), probabilistic=s.probabilistic,
                                     heads=list(model.heads))
        model.save(run_dir, metrics={k: v for k, v in summary.keys().items() if k not in ("env_id", "state_layout")})
        return self.finish(run_dir, settings, summary)

    def report(self, s: DynamicsFitSummary, settings: DynamicsFitSettings, console: Console) -> None:
        valid = f"valid_mse {s.valid_mse:.2e} (normalized)" if s.valid_mse is not None else "no validation"
        console.print(f"{valid} after {s.epochs_run} epochs, {s.wall_seconds:.1f} s -> {s.run_dir}/model.json, "
                      f"plots/loss.png")


DYNAMICS_FIT = DynamicsFitKind()


def require_box_actions(meta: dict[str, Any], source: str) -> None:
    """Refuse transitions of an env whose actions are not a Box (the model regresses on continuous
    actions); files that do not record their action space pass (motorlab's collect refuses the others).

    Raises:
        MotorlabError: one line naming the space.
    """
    space = meta.get("action_space")
    if space is None:
        return
    try:
        decoded = decode_space(space)
    except (KeyError, TypeError, ValueError) as e:
        raise MotorlabError(f"{source}: its action_space is damaged ({type(e).__name__}: {e}); re-run "
                            "`motorlab dynamics collect`.") from None
    env_id = meta.get("env_id", "ENV_ID")
    require_actions(decoded, f"dynamics fit ({source})", env_id=env_id,
                    instead=f"learn it model-free instead, e.g. `motorlab train {env_id} --algo ppo`")


# ---- dynamics-check ---------------------------------------------------------------------------


class DynamicsCheckSettings(Settings):
    model: str = Field(description="A model folder from `dynamics fit`")
    episodes: int = Field(5, gt=0, description="Open-loop episodes (random actions)")
    steps: int | None = Field(None, gt=0, description="Steps per episode (default: the env's time limit)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (initial states and actions)")


REACH_ERROR = "_error_mean_"  # <what reaches>_error_mean_h<k>: tip_error_mean_h5 for Reacher's fingertip


def _reach_scale(key: str) -> tuple[float, str]:
    reached = reaching(key.partition(REACH_ERROR)[0])
    return reached.scale if reached is not None else (1.0, "")


class DynamicsCheckSummary(Summary):
    """Also state_nrmse_h<k> for k in 1, 5, 10, 25 and _final, and for layouts that reach for a goal
    with part of the state (motorlab.dynamics.state.Reached) <key>_error_mean_h<k> and _final:
    tip_error_mean_h<k> for Reacher's fingertip, achieved_goal_error_mean_h<k> for a Dict goal."""

    env_id: str
    episodes: int
    horizon: int
    worst_dimension: str  # the state entry the model predicts worst, at worst_dimension_horizon steps ahead
    worst_dimension_nrmse: float
    worst_dimension_horizon: int


class DynamicsCheckKind(StepKind[DynamicsCheckSettings, DynamicsCheckSummary]):
    """Model vs simulator under the same actions, open loop: error vs horizon, x-y traces, summary numbers."""

    name = "dynamics-check"
    what = "check {model} open loop, {episodes} episodes"
    key_figures = ("plots/reach_error.png", "plots/error_by_dimension.png", "plots/traces.png")
    refs = (Ref("model", ("model",)),)
    arguments = ("model",)
    examples = ("motorlab dynamics check runs/reacher-model --episodes 5",)

    def run(self, settings: DynamicsCheckSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> DynamicsCheckSummary:
        from motorlab.dynamics.model import load_model
        from motorlab.dynamics.open_loop import REPORT_STEPS, open_loop, state_labels, write_error_table
        from motorlab.report.dynamics_plots import error_by_dimension, error_vs_horizon, xy_traces

        model = load_model(Path(settings.model))
        self.refuse_finished_out(out)
        r = open_loop(model, settings.episodes, settings.seed, settings.steps)
        run_dir = self.start(out)
        env_id = model.meta["env_id"]
        labels = state_labels(env_id, list(model.meta.get("state_labels") or []), model.state_size)
        scale = model.state_norm.std.numpy()  # state errors in units of each entry's spread in the data
        diff = r["model"] - r["true"]  # NaN after an episode's end
        last = diff.shape[1] - 1
        ends = r["live"].sum(1) - 1  # each episode's last step
        episodes = np.arange(len(diff))

        def at(errors: np.ndarray, h: int) -> float:  # mean over the episodes still going at step h
            return float(np.nanmean(errors[:, h]))

        nrmse = np.sqrt(((diff / scale) ** 2).mean(-1))  # (E, T+1)
        reported = [h for h in REPORT_STEPS if h <= last and r["live"][:, h].any()]
        keys: dict[str, Any] = {}
        # what the layout reaches for its goal with (Reacher's fingertip): its own error, in its own words
        reached = reached_of(model.meta.get("state_layout") or "", model.meta.get("state_labels") or [],
                             model.meta.get("goal_labels") or [])
        xy = list(reached.columns) if reached is not None and len(reached.columns) == 2 else None
        if reached is not None:
            gap = np.linalg.norm(diff[..., list(reached.columns)], axis=-1)
            keys.update({f"{reached.key}{REACH_ERROR}h{h}": at(gap, h) for h in reported})
            keys[f"{reached.key}{REACH_ERROR}final"] = float(gap[episodes, ends].mean())
            factor, unit = reached.scale
            error_vs_horizon(np.arange(last + 1), {reached.label: gap * factor}, run_dir / "plots" / "reach_error.png",
                             f"{env_id}: open-loop {reached.label} error",
                             f"{reached.label} error" + (f" ({unit})" if unit else ""))
        keys.update({f"state_nrmse_h{h}": at(nrmse, h) for h in reported})
        keys["state_nrmse_final"] = float(nrmse[episodes, ends].mean())
        error_vs_horizon(np.arange(last + 1), {"state (normalized RMSE)": nrmse},
                         run_dir / "plots" / "error_vs_horizon.png", f"{env_id}: model vs simulator, open loop",
                         "normalized RMSE")
        # each entry of the state (the observation's own dimensions, by default) on its own
        with np.errstate(invalid="ignore"):
            by_dim = np.sqrt(np.nanmean((diff / scale) ** 2, axis=0))  # (T+1, S)
        h_worst = max((h for h in (10, *reported) if h <= last and r["live"][:, h].any()), default=0)
        worst = int(np.nanargmax(by_dim[h_worst])) if np.isfinite(by_dim[h_worst]).any() else 0
        keys.update(worst_dimension=labels[worst], worst_dimension_nrmse=float(by_dim[h_worst, worst]),
                    worst_dimension_horizon=h_worst)
        write_error_table(run_dir / "error_by_dimension.csv", by_dim, labels)
        error_by_dimension(by_dim, labels, run_dir / "plots" / "error_by_dimension.png",
                           f"{env_id}: open-loop error of each state entry")
        cols = xy or [0, 1][:model.state_size]
        names = tuple(labels[c] for c in cols)
        xy_traces(r["true"][..., cols], r["model"][..., cols], r["goals"] if xy else None,
                  run_dir / "plots" / "traces.png", f"{env_id}: simulator vs model, {settings.episodes} episodes",
                  tuple(n + (f" ({reached.unit})" if xy and reached is not None and reached.unit else "") for n in names))
        atomic_write_npz(run_dir / "rollouts.npz", **r)
        summary = DynamicsCheckSummary(env_id=env_id, episodes=settings.episodes, horizon=last, **keys)
        return self.finish(run_dir, settings, summary)

    def headline(self, s: DynamicsCheckSummary) -> dict[str, Any]:
        return {k: v for k, v in s.keys().items() if REACH_ERROR in k or k.startswith("state_nrmse_")}

    def metric(self, key: str) -> Metric:
        horizon = key.rsplit("_", 1)[-1].removeprefix("h")  # "h10" -> "10", "final"
        where = "at the last step" if horizon == "final" else f"after {horizon} step{'s' * (horizon != '1')}"
        what, sep, _ = key.partition(REACH_ERROR)
        if sep and (reached := reaching(what)) is not None:
            factor, unit = reached.scale
            return Metric(key, f"{reached.label} error {where}", unit or "number", scale=factor)
        if key.startswith("state_nrmse_"):
            return Metric(key, f"state NRMSE {where}")
        return super().metric(key)

    def numbers(self, settings: DynamicsCheckSettings, h: dict[str, Any]) -> list[Number]:
        """The open-loop error of what reaches for the goal (Reacher's fingertip) where the layout has one,
        else the state's NRMSE."""
        reach = [k for k in h if REACH_ERROR in k]
        return [n for k in (reach or [k for k in h if k.startswith("state_nrmse_")]) if (n := self.metric(k).number(h))]

    def report(self, s: DynamicsCheckSummary, settings: DynamicsCheckSettings, console: Console) -> None:
        keys = s.keys()
        reach = [(k, v, _reach_scale(k)) for k, v in keys.items() if REACH_ERROR in k and not k.endswith("_final")]
        console.print("open-loop error: " + ", ".join(
            [f"{k.rsplit('_', 1)[-1]} {v * factor:.1f} {unit}".rstrip() for k, v, (factor, unit) in reach]
            or [f"{k.removeprefix('state_nrmse_')} {v:.3f}" for k, v in keys.items() if k.startswith("state_nrmse_h")]))
        console.print(f"worst entry: {s.worst_dimension} ({s.worst_dimension_nrmse:.3f} after "
                      f"{s.worst_dimension_horizon} steps); written: {s.run_dir}/error_by_dimension.csv, "
                      "plots/error_vs_horizon.png, error_by_dimension.png, traces.png")


DYNAMICS_CHECK = DynamicsCheckKind()
