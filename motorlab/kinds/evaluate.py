"""The `evaluate` and `zeroshot` step kinds: policies scored on their own env, and on envs
they never trained on."""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Annotated, Any, ClassVar

from pydantic import Field, model_validator
from rich.console import Console
from rich.table import Table

from motorlab.envs import (
    ENV_KEYS,
    EnvSettings,
    check_env_id,
    describe_env,
    early_end_label,
    fold_env,
    make_env,
    max_return,
    register_myosuite,
)
from motorlab.errors import MotorlabError
from motorlab.evaluation.rollouts import evaluate, success_by, success_mode, trained_env_settings
from motorlab.policies import BUILTIN_POLICIES, load_policy, unknown_policy_message
from motorlab.report.results import Metric, Number, fixed, show
from motorlab.runs import require_run_dir
from motorlab.settings import MAX_SEED, Settings, Summary, UserCode
from motorlab.stepkind import (
    SCORED_METRICS,
    Artifact,
    Ref,
    Scores,
    StepKind,
    scored_numbers,
    seeds_headline,
    warn_faults,
)

# ---- evaluate ---------------------------------------------------------------------------------


# The env worker processes of an evaluation (motorlab.evaluation.pool), as every evaluating kind takes them
EnvWorkers = Annotated[int | None, Field(
    ge=1, description="Processes stepping the envs, this one included (default: every core when the evaluation is "
    "large enough to pay for starting the others; 1: this process only); results are the same for any number")]


class EvaluateSettings(EnvSettings):
    """Evaluate a policy deterministically on an env (by default the one it trained on)."""

    aliases: ClassVar[frozenset[str]] = frozenset(ENV_KEYS) - {"reward"}  # returns are the task's own
    policy: str = Field(description="A run folder, or a built-in controller: pid, pid:kp=[..],ki=[..],kd=[..], "
                        "zero, random")
    episodes: int = Field(10, gt=0, description="Evaluation episodes")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (env resets: episode i starts from seed + i)")
    workers: EnvWorkers = None


class EvaluateSummary(Summary):
    policy: str
    env_id: str
    delay: float | str | None  # a range "LOW..HIGH" when drawn per episode
    history: int
    seed: int
    max_return: float | None
    success_mode: str
    success_by: str | None = None  # what a success is (rollouts.success_by); None in runs before it was kept
    episodes: int
    return_mean: float | None
    return_std: float | None
    return_min: float | None
    return_max: float | None
    success_rate: float | None
    episode_length_mean: float | None
    episode_lengths: list[int]
    falls: int
    numerical_faults: int


def is_folder_policy(policy: Any) -> bool:
    """Whether `policy` names a run folder that exists (not a built-in controller, nor a recipe's "@step")."""
    return isinstance(policy, (str, Path)) and not str(policy).startswith("@") and Path(policy).exists()


def merge_env(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """Env settings `overrides` on top of `base`; env keyword arguments merge key by key."""
    merged = {**base, **{k: v for k, v in overrides.items() if v is not None}}
    if isinstance(base.get("kwargs"), dict) and isinstance(overrides.get("kwargs"), dict):
        merged["kwargs"] = {**base["kwargs"], **overrides["kwargs"]}
    return merged


class EvaluateKind(StepKind[EvaluateSettings, EvaluateSummary]):
    """Evaluate a policy deterministically; print a table, write summary.json.

    summary.json: return_mean, return_std, return_min, return_max, success_rate,
    episode_lengths. Returns are the task's own (training-time reward shaping is not applied).
    By default a run folder's policy acts in the env it trained in (its id, arguments, delay,
    history and synergies); the env settings given here go on top.
    """

    name = "evaluate"
    arguments = ("policy",)
    examples = (
        "motorlab evaluate runs/ppo --delay 0.2 --episodes 20",
        "motorlab evaluate pid --env InvertedPendulum-v5",
        "motorlab evaluate 'pid:kp=[1,20,0,0],kd=[1,3,0,0]' --env InvertedPendulum-v5",
    )
    refs = (Ref("policy", ("policy",)), Ref("sar", ("sar",)))
    provides = Artifact("evaluation")
    scored = True
    per_seed = True
    metrics = SCORED_METRICS

    def prepare(self, fields: dict[str, Any], referenced: dict[str, Settings]) -> dict[str, Any]:
        trained = getattr(referenced.get("policy"), "env", None)
        if trained is None:
            return fields
        # by default, evaluate on the env the policy was trained on, without its reward shaping
        trained_env = trained.model_dump(exclude={"reward"})
        sar = trained_env.pop("sar", None)
        data = fold_env(fields)
        data["env"] = merge_env(trained_env, data["env"])
        if sar and "sar" not in data["env"]:  # in the synergy space it trained in; "@fit": once that step ran
            data["sar"] = sar
        return data

    def validate(self, fields: dict[str, Any]) -> EvaluateSettings:
        """Settings from flat or folded fields; a run folder's policy acts in the env it trained in
        (without its reward shaping), under the env settings given."""
        if is_folder_policy(fields.get("policy")):
            data = fold_env(fields)
            data["env"] = merge_env(trained_env_settings(require_run_dir(Path(fields["policy"]))), data["env"])
            fields = data
        return super().validate(fields)

    def make(self, how: Any = None, /, **fields: Any) -> EvaluateSettings:
        """Settings as the command line and the Python API give them.

        Raises:
            MotorlabError: a policy that is neither a run folder nor a built-in controller, no env
                id known (a built-in controller without --env), a bad setting.
        """
        policy = fields.get("policy")
        if isinstance(policy, str) and not is_folder_policy(policy) and not policy.startswith("@") \
                and policy.split(":", 1)[0] not in BUILTIN_POLICIES:
            raise MotorlabError(unknown_policy_message(policy))
        settings = super().make(how, **fields)
        if "id" not in settings.env.model_fields_set:
            raise MotorlabError(f"no env for {policy!r}: give --env ENV_ID (e.g. --env InvertedPendulum-v5).")
        return settings

    def check(self, settings: EvaluateSettings) -> None:
        make_env(settings.env).close()

    def run(self, settings: EvaluateSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> EvaluateSummary:
        env_cfg = settings.env
        probe = make_env(env_cfg, shaped=False)
        try:
            policy = load_policy(settings.policy, probe, env_cfg.id, settings.seed)
            target = max_return(env_cfg.id)
        finally:
            probe.close()
        self.refuse_finished_out(out)
        result = evaluate(policy, env_cfg, settings.episodes, settings.seed, workers=settings.workers)
        run_dir = self.start(out)
        summary = EvaluateSummary(policy=settings.policy, env_id=env_cfg.id, delay=env_cfg.delay,
                                  history=env_cfg.history, seed=settings.seed, max_return=target,
                                  success_mode=success_mode(env_cfg), success_by=success_by(env_cfg, result.success_key),
                                  **result.summary())
        return self.finish(run_dir, settings, summary, result.fault_log)

    def describe(self, settings: EvaluateSettings, copies: int = 1) -> str:
        return f"evaluate {settings.policy} · {describe_env(settings.env)}"

    def scores(self, s: EvaluateSummary) -> Scores:
        return Scores(s.return_mean, s.return_std, s.return_min, s.success_rate, s.episodes,
                      s.episode_length_mean, s.falls)

    def headline(self, s: EvaluateSummary) -> dict[str, Any]:
        head = {"return_mean": s.return_mean, "return_std": s.return_std, "return_min": s.return_min,
                "success_rate": s.success_rate, "episode_length_mean": s.episode_length_mean, "falls": s.falls,
                "episodes": s.episodes, "success_by": s.success_by}
        return {k: v for k, v in head.items() if v is not None}

    def aggregate(self, summaries: list[EvaluateSummary]) -> dict[str, Any]:
        if len(summaries) == 1:
            return self.headline(summaries[0])
        return {**seeds_headline([self.scores(s) for s in summaries]), "falls": sum(s.falls for s in summaries),
                "success_by": summaries[0].success_by,
                "episode_length_mean": statistics.fmean(s.episode_length_mean for s in summaries)}

    def numbers(self, settings: EvaluateSettings, h: dict[str, Any]) -> list[Number]:
        return scored_numbers(self.metrics, h, settings.env.id)

    def default_findings(self, settings: EvaluateSettings, h: dict[str, Any]) -> list[str]:
        return ["success_rate" if h.get("success_rate") is not None else "return_mean"]

    def figures(self, run_dir: Path) -> None:
        from motorlab.media.figures import plot_run

        plot_run(run_dir)

    def report(self, s: EvaluateSummary, settings: EvaluateSettings, console: Console) -> None:
        env_cfg = settings.env
        table = Table(title=f"{settings.policy} on {describe_env(env_cfg)}")
        for col in ("episodes", "return mean ± std", "min", "max", "success", "mean length",
                    early_end_label(env_cfg.id)):
            table.add_column(col, justify="right")
        table.add_row(str(s.episodes), f"{fixed(s.return_mean, '.1f')} ± {fixed(s.return_std, '.1f')}",
                      fixed(s.return_min, ".1f"), fixed(s.return_max, ".1f"), fixed(s.success_rate, ".0%"),
                      fixed(s.episode_length_mean, ".0f"), str(s.falls))
        console.print(table)
        super().report(s, settings, console)  # written: summary.json, and a warning on numerical faults


EVALUATE = EvaluateKind()


# ---- zeroshot ---------------------------------------------------------------------------------

RESULT_KEYS = ("success_rate", "return_mean", "return_std", "numerical_faults")


class ZeroshotSettings(Settings):
    runs: list[str] = Field(min_length=1, description="Training run folders to compare")
    envs: Annotated[list[str], UserCode(check_env_id)] = Field(min_length=1, description="Env ids the policies "
                                                                "never trained on")
    episodes: int = Field(500, gt=0, description="Episodes per run and env")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (env resets)")
    workers: EnvWorkers = None

    @model_validator(mode="before")
    @classmethod
    def _env_ids_among_runs(cls, data: Any) -> Any:
        """`--envs A B` on the command line gives B to the runs: an entry of `runs` that is no path
        but an env id belongs to `envs`; envs may also be written A,B.

        Raises:
            MotorlabError: no run folder or no env left.
        """
        if not isinstance(data, dict) or "runs" not in data:
            return data  # nothing to sort (a missing field is the model's own error)
        runs = [str(r) for r in _listed(data.get("runs"), "runs")]
        envs = [e for item in _listed(data.get("envs"), "envs") for e in str(item).split(",") if e]
        maybe_env = [r for r in runs if not r.startswith("@") and not Path(r).exists()]
        if maybe_env:
            import gymnasium as gym

            register_myosuite()  # its ids, when MyoSuite is installed
            moved = [r for r in maybe_env if r in gym.registry]
            runs = [r for r in runs if r not in moved]
            envs = [*envs, *(e for r in moved for e in r.split(",") if e)]
        if not runs or not envs:
            raise MotorlabError(f"{'--runs' if not runs else '--envs'}: give at least one run folder and one env "
                                "(--envs ID ...).")
        return {**data, "runs": runs, "envs": envs}


def _listed(value: Any, field: str) -> list[str | Path]:
    """A list field's value as a list (one value: a list of it; none: empty).

    Raises:
        MotorlabError: an item that is no text (a number, a table): folder names and env ids are text.
    """
    if value is None:
        return []
    items = list(value) if isinstance(value, (list, tuple)) else [value]
    wrong = next((item for item in items if not isinstance(item, (str, Path))), None)
    if wrong is not None:
        raise MotorlabError(f"--{field} {wrong!r}: give {'run folders' if field == 'runs' else 'env ids'} as text.")
    return items


class ZeroshotSummary(Summary):
    """Also "<run>.<env>.success_rate", "<run>.<env>.return_mean", ... for every run and env."""

    runs: list[str]
    envs: list[str]
    episodes: int
    seed: int
    numerical_faults: int


class ZeroshotKind(StepKind[ZeroshotSettings, ZeroshotSummary]):
    """Zero-shot success of trained policies on unseen envs: table, summary.json, grouped bar chart."""

    name = "zeroshot"
    key_figures = ("plots/zeroshot.png",)
    refs = (Ref("runs", ("policy",)),)
    arguments = ("runs",)
    examples = ("motorlab zeroshot runs/sar-rl runs/rl-e2e --envs myoHandReorientID-v0 myoHandReorientOOD-v0 "
                "--episodes 500",)

    def run(self, settings: ZeroshotSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> ZeroshotSummary:
        from motorlab.evaluation.zeroshot import transfer
        from motorlab.report.plots import grouped_bars

        t = transfer([Path(r) for r in settings.runs], settings.envs, settings.episodes, settings.seed,
                     workers=settings.workers, before_work=lambda: self.refuse_finished_out(out))
        run_dir = self.start(out)
        grouped_bars(t.envs, {n: [_or_nan(t.results[n][e]["success_rate"]) for e in t.envs] for n in t.names},
                     "success rate", run_dir / "plots" / "zeroshot.png",
                     f"Zero-shot success ({settings.episodes} episodes per env)",
                     f"Success rate of each trained policy on envs it never trained on, {settings.episodes} "
                     "episodes per env.", percent=True)
        table = Table(title=f"zero-shot: {settings.episodes} episodes per env, seed {settings.seed}")
        table.add_column("run")
        for env_id in t.envs:
            table.add_column(f"{env_id} success", justify="right")
            table.add_column("return", justify="right")
        for n in t.names:
            table.add_row(n, *[cell for env_id in t.envs for cell in
                               (fixed(t.results[n][env_id]['success_rate'], ".1%"),
                                fixed(t.results[n][env_id]['return_mean'], ".1f"))])
        (console or Console()).print(table)
        per_run = {f"{n}.{env_id}.{key}": t.results[n][env_id][key]
                   for n in t.names for env_id in t.envs for key in RESULT_KEYS}
        summary = ZeroshotSummary(runs=t.names, envs=t.envs, episodes=settings.episodes, seed=settings.seed,
                                  numerical_faults=len(t.fault_log), **per_run)
        return self.finish(run_dir, settings, summary, t.fault_log)

    def describe(self, settings: ZeroshotSettings, copies: int = 1) -> str:
        return f"zero-shot {', '.join(settings.runs)} on {', '.join(settings.envs)}"

    def headline(self, s: ZeroshotSummary) -> dict[str, Any]:
        per_run = {k: v for k, v in s.keys().items() if "." in k}
        groups: dict[str, list[float]] = {}  # "<step>.<env>.success_rate_mean": the mean over a step's seeds
        for key, value in per_run.items():
            if key.endswith(".success_rate") and value is not None:
                label, env_id, _ = key.rsplit(".", 2)
                groups.setdefault(f"{label.split('/')[0]}.{env_id}", []).append(value)
        return {**per_run, **{f"{k}.success_rate_mean": statistics.fmean(v) for k, v in groups.items()}}

    def metric(self, key: str) -> Metric:
        if key.endswith(".success_rate_mean"):  # "<step>.<env>.success_rate_mean"
            step, env_id = key[: -len(".success_rate_mean")].split(".", 1)
            return Metric(key, f"{step} on {env_id}: success", "percent")
        if key.endswith(".success_rate"):
            return Metric(key, f"{key[: -len('.success_rate')].replace('.', ' on ', 1)}: success", "percent")
        return super().metric(key)

    def numbers(self, settings: ZeroshotSettings, h: dict[str, Any]) -> list[Number]:
        """Success of each trained step on each env (the mean over its seeds)."""
        return [n for k in h if k.endswith(".success_rate_mean") and (n := self.metric(k).number(h))]

    def default_findings(self, settings: ZeroshotSettings, h: dict[str, Any]) -> list[str]:
        return [k for k in h if k.endswith(".success_rate_mean")]

    def seed_values(self, runs: list[tuple[str, ZeroshotSummary]], key: str) -> list[tuple[str, Any]]:
        if not key.endswith(".success_rate_mean"):
            return super().seed_values(runs, key)
        step, env_id = key[: -len(".success_rate_mean")].split(".", 1)
        (_, s), = runs  # one zero-shot run holds every seed of the steps it compares
        return [(label.split("/", 1)[-1], v) for k, v in s.keys().items()
                if k.endswith(f".{env_id}.success_rate") and (label := k[: -len(f".{env_id}.success_rate")])
                .split("/")[0] == step]

    def notes(self, settings: ZeroshotSettings, h: dict[str, Any]) -> str:
        return f"success: mean over each step's seeds, {show(settings.episodes, 'count')} episodes per env"

    def report(self, s: ZeroshotSummary, settings: ZeroshotSettings, console: Console) -> None:
        console.print(f"written: {s.run_dir}/summary.json, {s.run_dir}/plots/zeroshot.png")  # the table: in `run`
        warn_faults(s)


ZEROSHOT = ZeroshotKind()


def _or_nan(value: float | None) -> float:
    """A bar's height: NaN (no bar) where the env defines no success."""
    return float("nan") if value is None else value
