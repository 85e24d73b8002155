"""The `train` step kind: one policy trained as its settings say, one run folder."""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Any

from pydantic import Field, PrivateAttr
from rich.console import Console

from motorlab.command import Tracked
from motorlab.envs import describe_env, fold_env
from motorlab.errors import MotorlabError
from motorlab.report.results import Metric, Number
from motorlab.rl.config import TrainConfig, resolve
from motorlab.runs import FolderMode, is_complete, last_timesteps
from motorlab.settings import Summary
from motorlab.stats import steps_to_success
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
    stopped_by: str = "timesteps"  # timesteps, minutes (--minutes) or solved (--until-solved)
    minutes: float | None = None  # the wall-clock budget given, if any
    train_seconds: float | None = None  # wall seconds of training (evaluations, checkpoints not counted)
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
    # a resumed run says so to `report` (its resumed_from is None where no checkpoint was left); not in summary.json
    _resumed: bool = PrivateAttr(False)


class TrainInvocation(Tracked):
    """How `motorlab train` runs: --out, --overwrite, --track, and where its settings come from
    (--config) or which interrupted run it continues (--resume)."""

    config: Path | None = Field(None, description="Start from a run's config.toml (repeat a run, or run one a sweep "
                                "or study planned); flags given here override it")
    resume: Path | None = Field(None, description="Continue the interrupted run in this folder from its last "
                                "checkpoint, to the same total budget, with its own settings")

    def mode(self) -> FolderMode:
        if self.resume is not None and self.overwrite:
            raise MotorlabError(f"--resume continues {self.resume} and --overwrite replaces it; give one of them.")
        return super().mode()


class TrainKind(StepKind[TrainConfig, TrainSummary]):
    """Train a policy on ENV_ID and write a run folder.

    The folder holds config.toml, metrics.csv, tensorboard/, the policy (policy.json +
    policy.safetensors, pickle-free; SB3's model.zip for continuing training) and
    summary.json with steps_to_success (null if the budget ran out first) and wall_seconds.
    """

    name = "train"
    BUDGET = "timesteps"
    arguments = ("env",)
    flags = {"hyperparams": ("--set",)}
    invocation = TrainInvocation
    examples = (
        "motorlab train InvertedPendulum-v5 --until-solved --out runs/ppo",
        "motorlab train InvertedPendulum-v5 --preset fast --delay 0.2 --until-solved",
        "motorlab train InvertedPendulum-v5 --preset-file runs/tune/best.toml --seed 7",
        "motorlab train InvertedPendulum-v5 --algo ppo --lr linear:3e-4,0 --clip-range linear:0.3,0.1 --history 10 "
        "--delay 0.2",
        "motorlab train Upkie-PyBullet-Pendulum --n-envs 2 --timesteps 150000 --env-arg 'init_rand={\"pitch\": 0.1}'",
        "motorlab train --config runs/ppo/config.toml --seed 1 --out runs/ppo-seed1   # a run again, on another seed",
        "motorlab train --resume runs/ppo   # go on after an interruption",
    )
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
        fields = dict(fields)
        if isinstance(fields.get("preset_file"), (str, Path)):  # config.toml records where it was read
            if "\x00" in str(fields["preset_file"]):
                raise MotorlabError(f"--preset-file {str(fields['preset_file'])!r}: a path holds no NUL character.")
            fields["preset_file"] = str(Path(fields["preset_file"]).resolve())
        return resolve(fields)  # the named preset under the given settings

    def fields_for(self, how: TrainInvocation, given: dict[str, Any]) -> dict[str, Any]:
        """What `make` validates on a command line (or in a job): with --config, that run's
        config.toml under the fields given; with --resume, the interrupted run's own settings (only
        the progress bar may be given); else the fields given, which must name an env.

        Raises:
            MotorlabError: no env id and no --config; --resume with other settings, or of a folder
                that holds no interrupted training run; a config.toml that cannot be read.
        """
        if how.resume is not None:
            if set(given) - {"progress"} or how.config is not None or how.out is not None:
                raise self._resume_alone(Path(how.resume))
            return self._own_fields(Path(how.resume), given.get("progress", True))
        if how.config is not None:
            merged = super().fields_for(how, given)
            if "progress" not in given:  # the progress bar is the flags' (on by default), never the config's
                merged.pop("progress", None)
            return merged
        if "id" not in fold_env(given)["env"]:
            raise MotorlabError("give an env id (motorlab train InvertedPendulum-v5) or --config RUN/config.toml.")
        return given

    def execute(self, settings: TrainConfig, how: TrainInvocation, console: Console | None,
                progress: bool) -> TrainSummary:
        """Train as the settings say (`make(how, ...)` laid the flags over --config's config.toml);
        with --resume, continue the interrupted run in that folder, on its own settings."""
        if how.resume is None:
            return super().execute(settings, how, console, progress)
        run_dir = Path(how.resume)
        if how.config is not None or how.out is not None:
            raise self._resume_alone(run_dir)
        own = self.validate(self._own_fields(run_dir, settings.progress))
        if settings.model_dump() != own.model_dump():  # settings made without `how`: not the run's own
            raise self._resume_alone(run_dir)
        summary = self.perform(own, run_dir, folders=how.mode(), track=how.track, resume=True, console=console,
                               progress=progress)
        summary._resumed = True
        return summary

    def _own_fields(self, run_dir: Path, progress: bool) -> dict[str, Any]:
        """The settings of the interrupted run in `run_dir` (its config.toml), with the progress bar given."""
        if not (run_dir / "config.toml").is_file():
            raise MotorlabError(f"{run_dir} is not a training run folder (no config.toml); give the --out of the "
                                "interrupted motorlab train.")
        if is_complete(run_dir):
            raise MotorlabError(f"{run_dir} finished already (it has summary.json); there is nothing to resume.")
        return {**self.with_config(run_dir / "config.toml", {}), "progress": progress}

    @staticmethod
    def _resume_alone(run_dir: Path) -> MotorlabError:
        return MotorlabError(f"--resume continues {run_dir} with the settings in its config.toml; "
                             "drop the other settings (and --out, --config).")

    def report(self, s: TrainSummary, settings: TrainConfig, console: Console) -> None:
        start = s.resumed_from
        if start is not None or s._resumed:  # resumed (with no checkpoint left: started over)
            console.print(f"[green]done[/green] {s.run_dir}: "
                          + (f"resumed at {start:,} steps; " if start else "no checkpoint yet, started over; ")
                          + f"return {s.eval_return_mean:.1f} over {s.eval_episodes} episodes, {s.timesteps:,} steps")
        else:
            sts = s.steps_to_success
            console.print(f"[green]done[/green] {s.run_dir}: "
                          f"return {s.eval_return_mean:.1f} (min {s.eval_return_min:.0f}) over "
                          f"{s.eval_episodes} episodes, {s.timesteps:,} steps, {s.wall_seconds:.1f} s"
                          + (f", steps_to_success {sts:,}" if sts is not None
                             else (", not solved" if s.until_solved else "")))
        warn_faults(s)

    def run(self, settings: TrainConfig, out: Path | None = None, console: Console | None = None,
            progress: bool = True, resume: bool = False) -> TrainSummary:
        from motorlab.rl.train import finished, train

        if not progress:
            settings = settings.model_copy(update={"progress": False})
        done = train(settings, out, resume=resume, start=self.start)
        run_dir = Path(done.pop("run_dir"))
        summary = self.finish(run_dir, settings, TrainSummary.model_validate(done))  # config, results, summary.json
        finished(run_dir)
        return summary

    def check(self, settings: TrainConfig) -> None:
        from motorlab.rl.envcheck import check_train_env

        # a bad id, delay or reward, an algorithm that does not fit the env, --her misused: before any step runs
        check_train_env(settings)
        from motorlab.rl.sb3 import ALGORITHMS, check_hyperparams

        if settings.algo in ALGORITHMS:  # SB3's take keyword arguments; the LQR learner takes none
            check_hyperparams(settings.algo, settings.hyperparams)  # unknown names, wrong types

    def stops_early(self, settings: TrainConfig) -> bool:
        return settings.until_solved

    def budget(self, headline: dict[str, Any]) -> int | None:
        return self.planned_steps_of(headline)  # a train summary records the run's budget as its config does

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
        # a seed that never solved is censored at the steps it ran (its budget), never counted as a
        # value; the Kaplan-Meier median is None (above the budget) when fewer than half solved
        reached = steps_to_success([s.steps_to_success for s in summaries], [s.timesteps for s in summaries])
        return {**seeds_headline([self.scores(s) for s in summaries]),
                "train_success_rate_last100": statistics.fmean(rates) if None not in rates else None,
                "steps_to_success": reached.median,
                "steps_to_success_solved": reached.solved,
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
        from motorlab.media.figures import plot_run

        plot_run(run_dir)

    def progress(self, settings: TrainConfig, run_dir: Path) -> tuple[int, int]:
        return last_timesteps(run_dir), settings.timesteps

    def warm_up(self) -> None:
        import motorlab.media.figures  # noqa: F401  (the study's figures: SB3 policies, torch)
        import motorlab.rl.checkpoint  # noqa: F401  (can_resume, in the background thread)
        import motorlab.rl.sb3  # noqa: F401  (torch and SB3 themselves: the modules above import them when used)

    def can_resume(self, run_dir: Path) -> bool:
        from motorlab.rl.checkpoint import has_checkpoint

        return has_checkpoint(run_dir)


TRAIN = TrainKind()
