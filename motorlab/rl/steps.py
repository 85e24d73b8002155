"""The `train` step kind: one policy trained as its settings say, one run folder."""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Any

from rich.console import Console

from motorlab.envs import describe_env
from motorlab.report.results import Metric, Number, write_run_results
from motorlab.rl.config import TrainConfig, resolve
from motorlab.runs import last_timesteps
from motorlab.settings import Summary
from motorlab.stepkind import SCORED_METRICS, Artifact, Ref, Scores, StepKind, scored_numbers, seeds_headline


class TrainSummary(Summary):
    """summary.json of a training run; eval_* is the final evaluation of the saved policy."""

    env_id: str
    algo: str
    preset: str | None
    seed: int
    delay: float | str | None
    history: int
    timesteps: int
    budget: int
    until_solved: bool
    solve_return: float | None
    steps_to_success: int | None
    solved: bool
    wall_seconds: float
    evaluations: int
    train_episodes: int
    train_success_rate_last100: float | None
    success_mode: str
    success_by: str | None = None  # what a success is (evaluation.success_by); None in runs before it was kept
    numerical_faults: int
    resumed_from: int | None
    eval_seed: int
    eval_episodes: int
    eval_return_mean: float | None
    eval_return_std: float | None
    eval_return_min: float | None
    eval_return_max: float | None
    eval_success_rate: float | None
    eval_episode_length_mean: float | None
    eval_falls: int
    eval_numerical_faults: int
    eval_episode_lengths: list[int]


class TrainKind(StepKind[TrainConfig, TrainSummary]):
    """Train a policy (PPO, SAC, TD3 or the model-based LQR learner) on an env."""

    name = "train"
    refs = (Ref("sar", ("sar",)),)  # train in the synergy space a fit step made
    provides = Artifact("policy")
    scored = True
    trains = True
    metrics = (*SCORED_METRICS[:4],
               Metric("steps_to_success", "steps to success", "steps"),
               Metric("train_success_rate_last100", "training success (last 100 episodes)", "percent"),
               *SCORED_METRICS[4:],
               Metric("timesteps", "trained for", "steps", setup=True),
               Metric("wall_seconds", "training time", "s", setup=True))

    def validate(self, fields: dict[str, Any]) -> TrainConfig:
        return resolve(fields)  # the named preset under the given settings

    def run(self, settings: TrainConfig, out: Path | None = None, console: Console | None = None,
            progress: bool = True, resume: bool = False) -> TrainSummary:
        from motorlab.rl.train import train

        if not progress:
            settings = settings.model_copy(update={"progress": False})
        summary = TrainSummary.model_validate(done := train(settings, out, resume=resume))
        write_run_results(Path(done["run_dir"]), self.results(settings, summary))
        return summary

    def check(self, settings: TrainConfig) -> None:
        from motorlab.rl.envcheck import check_train_env

        # a bad id, delay or reward, an algorithm that does not fit the env, --her misused: before any step runs
        check_train_env(settings)
        if settings.algo != "lqr":
            from motorlab.rl.sb3 import check_hyperparams

            check_hyperparams(settings.algo, settings.hyperparams)  # unknown names, wrong types

    def describe(self, settings: TrainConfig, copies: int = 1) -> str:
        what = (settings.preset or settings.algo) + (" + HER" if settings.her else "") + (
            " until solved" if settings.until_solved else f" {settings.timesteps:,} steps")
        if copies > 1:
            what += f" × {copies} seeds"
        return f"{what} · {describe_env(settings.env)}"

    def scores(self, s: TrainSummary) -> Scores:
        return Scores(s.eval_return_mean, s.eval_return_std, s.eval_return_min, s.eval_success_rate,
                      s.eval_episodes, s.eval_episode_length_mean, s.eval_falls)

    def headline(self, s: TrainSummary) -> dict[str, Any]:
        e = self.scores(s)
        head = {"return_mean": e.return_mean, "return_std": e.return_std, "return_min": e.return_min,
                "success_rate": e.success_rate, "steps_to_success": s.steps_to_success, "timesteps": s.timesteps,
                "wall_seconds": s.wall_seconds, "episode_length_mean": e.episode_length_mean, "falls": e.falls,
                "episodes": e.episodes, "train_success_rate_last100": s.train_success_rate_last100,
                "success_by": s.success_by}
        return {k: v for k, v in head.items() if v is not None or k == "steps_to_success"}

    def aggregate(self, summaries: list[TrainSummary]) -> dict[str, Any]:
        if len(summaries) == 1:
            return self.headline(summaries[0])
        rates = [s.train_success_rate_last100 for s in summaries]
        solved = [s.steps_to_success for s in summaries]
        return {**seeds_headline([self.scores(s) for s in summaries]),
                "train_success_rate_last100": statistics.fmean(rates) if None not in rates else None,
                # a seed that never solved makes the median unknowable, not smaller
                "steps_to_success": statistics.median(solved) if None not in solved else None,
                "success_by": summaries[0].success_by,
                "timesteps": sum(s.timesteps for s in summaries),
                "wall_seconds": sum(s.wall_seconds for s in summaries)}

    def numbers(self, settings: TrainConfig, h: dict[str, Any]) -> list[Number]:
        numbers = scored_numbers(self.metrics, h, settings.env.id)
        if h.get("seeds"):  # budgets of several seeds are their sums
            numbers = [Number(n.key, f"{n.label} (all seeds)", n.value, n.text, n.setup)
                       if n.key in ("timesteps", "wall_seconds") else n for n in numbers]
        if settings.until_solved and h.get("steps_to_success") is None:  # asked to solve, and did not
            numbers.insert(4, Number("steps_to_success", "steps to success", None, "not reached"))
        return numbers

    def default_findings(self, settings: TrainConfig, h: dict[str, Any]) -> list[str]:
        return (["steps_to_success"] if settings.until_solved else []) + \
            ["success_rate" if h.get("success_rate") is not None else "return_mean"]

    def figures(self, run_dir: Path) -> None:
        from motorlab.report.run import plot_run

        plot_run(run_dir)

    def progress(self, settings: TrainConfig, run_dir: Path) -> tuple[int, int]:
        return last_timesteps(run_dir), settings.timesteps

    def process_argv(self, settings_file: Path, run_dir: Path) -> list[str]:
        return [*self.command.split(), "--config", str(settings_file), "--out", str(run_dir), "--no-progress"]

    def warm_up(self) -> None:
        import motorlab.report.run  # noqa: F401  (the study's figures: SB3 policies, torch)
        import motorlab.rl.checkpoint  # noqa: F401  (resume_argv, in the background thread)
        import motorlab.rl.sb3  # noqa: F401  (torch and SB3 themselves: the modules above import them when used)

    def resume_argv(self, run_dir: Path) -> list[str] | None:
        from motorlab.rl.checkpoint import has_checkpoint

        if has_checkpoint(run_dir):
            return [*self.command.split(), "--resume", str(run_dir), "--no-progress"]
        return None


TRAIN = TrainKind()
