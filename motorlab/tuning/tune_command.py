"""`motorlab tune`: an Optuna search over a command's or a recipe's settings, as a command."""

from __future__ import annotations

import shlex
from typing import TYPE_CHECKING, Any, ClassVar, Literal

from pydantic import Field, field_serializer, field_validator
from rich.console import Console

from motorlab.command import Command, Resumable
from motorlab.errors import mask_url
from motorlab.settings import MAX_SEED, MAX_SEEDS
from motorlab.sweeps.targets import TargetSettings

if TYPE_CHECKING:
    from motorlab.tuning.space import Space


class TuneSettings(TargetSettings):
    # the target (TargetSettings) and the space are read once, here: from the command line's text, or as Python
    # gives them (a `StepTarget` / `RecipeTarget`; Optuna distributions)
    owner: ClassVar[str] = "tune"

    space: list[str] | dict[str, Any] = Field(description=(
        "KEY=DIST: loguniform:LOW,HIGH, uniform:LOW,HIGH, int:LOW,HIGH or choice:A,B,C. KEY: a setting (lr, n_envs, "
        "delay), a recipe FIELD or STEP.FIELD, or an SB3 hyperparameter (set.KEY, or any KEY that is not a setting)"))
    trials: int = Field(20, ge=1, description="Trials in all (COMPLETE and PRUNED), over every process sharing the "
                        "study")
    seeds: int = Field(3, ge=1, description="Seeds per trial (0..K-1); its value is their IQM (the "
                       "mean below 4 seeds; for steps_to_success their restricted mean)")
    objective: str = Field("steps_to_success", description=(
        "steps_to_success (the seeds' restricted mean: an unsolved seed at its budget; shown as k of n solved "
        "and their censored median), final_return, success_rate, or any number in the runs' "
        "summary.json (a study's: STEP.METRIC)"))
    direction: Literal["max", "min"] | None = Field(None, description="max or min (default: min for "
                                                    "steps_to_success, else max)")
    storage: str | None = Field(None, description="Database URL of the study (default sqlite:///OUT/study.db); any "
                                "URL Optuna accepts")
    study_name: str | None = Field(None, description="Study name in the database (default: derived from the target, "
                                   "space, objective and seeds)")
    sampler: Literal["tpe", "random", "cmaes"] = Field("tpe", description="Optuna's sampler: tpe, random or cmaes")
    sampler_seed: int | None = Field(None, ge=0, le=MAX_SEED, description=(
        "Seed of the sampler: the same command samples the same settings (a resumed search goes on from where it "
        "was). Several processes sharing one search: leave it out or give each its own"))
    pruner: Literal["median", "hyperband", "none"] = Field("median", description=(
        "median, hyperband or none (with --backend ray, Tune's schedulers: ASHA, ASHA with 3 brackets, none)"))
    prune_startup: int = Field(5, ge=0, description="Finished trials before the median pruner prunes")
    report_every: int = Field(1000, ge=1, description="Env steps between the intermediate numbers reported to the "
                              "pruner")
    fresh_seeds: int | None = Field(None, ge=0, le=MAX_SEEDS, description="Seeds the best settings are re-run on after the search "
                                    "(default: --seeds; 0: none)")

    @field_validator("space")
    @classmethod
    def _read_space(cls, value: list[str] | dict[str, Any]) -> Space:
        from motorlab.tuning.space import Space, parse_space  # Optuna: imported when a search is made, not for --help

        return Space(parse_space(value))

    @field_serializer("space")
    def _space_items(self, space: Space) -> list[str]:
        """config.toml records the space as --space's KEY=KIND:ARGS items, which read back to the same space."""
        return [d.item() for d in space.dists.values()]


class TuneCommand(Command[TuneSettings]):
    """Search settings with Optuna, judging each trial by the IQM of its objective over several seeds.

    Writes study.db, trials.csv, table.txt, best.toml (a preset file for train --preset-file),
    plots/, summary.json (with the best settings' numbers on fresh seeds) and report.html in the
    folder, and each trial's run folders under trials/<number>/seed<k>/. Run the same command
    again (same --out) to resume; several processes with the same --out (or --storage) share one
    search.
    """

    name = "tune"
    invocation = Resumable
    arguments = ("target",)
    examples = (
        'motorlab tune "train InvertedPendulum-v5 --algo ppo --timesteps 50000 --until-solved" --space '
        "lr=loguniform:1e-5,1e-2 --space n_steps=choice:256,512,1024 --trials 40 --seeds 3 --objective "
        "steps_to_success --out runs/tune-ppo",
        "motorlab tune pendulum --space ppo.timesteps=int:20000,100000 --trials 10 --seeds 2 --objective "
        "ppo.final_return   # a whole study per seed",
        "motorlab train InvertedPendulum-v5 --preset-file runs/tune-ppo/best.toml --seed 7",
        'motorlab tune "train Reacher-v5 --algo sac --timesteps 100000" --space lr=loguniform:1e-4,1e-3 --trials 50 '
        "--seeds 3 --objective final_return --backend ray --address 10.0.0.5:6379   # Ray Tune: OptunaSearch, ASHA")

    def execute(self, settings: TuneSettings, how: Resumable, console: Console | None, progress: bool) -> Any:
        from motorlab.tuning.tune import make_spec, run_tune

        s = settings
        spec = make_spec(s.target, s.space.dists, s.trials, s.seeds, s.objective, s.direction, how.out, s.storage,
                         s.study_name, s.sampler, s.pruner, s.prune_startup, s.report_every, s.max_parallel,
                         s.fresh_seeds, backend=s.backend, address=s.address, sampler_seed=s.sampler_seed)
        return {**run_tune(spec, s.target, console=console), "storage": spec.storage}

    def report(self, result: Any, settings: TuneSettings, console: Console) -> None:
        console.print(f"\n[bold]Results:[/bold] {result['tune_dir']}  (best.toml, trials.csv, table.txt, "
                      "summary.json, plots/*.png, report.html, study.db)")
        shown = mask_url(result["storage"])
        console.print(f"The study in a browser: optuna-dashboard {shlex.quote(shown)}"
                      + (" (with the password in place of ***)" if shown != result["storage"] else ""))


TUNE = TuneCommand()
