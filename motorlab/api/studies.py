"""Studies, sweeps and searches from Python: `motorlab run`, `motorlab sweep`, `motorlab tune`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab import trackers
from motorlab.api.checks import api_function
from motorlab.api.running import Track, console, folders, path_of
from motorlab.api.views import Study, Sweep, Tune
from motorlab.errors import MotorlabError
from motorlab.sweeps.targets import RecipeTarget, StepTarget, Target, recipe_target, step_target


@api_function
def run_recipe(recipe: str | Path, out: str | Path | None = None, *, backend: str = "local",
               address: str | None = None, max_parallel: int | None = None, parallel_steps: int | None = None,
               track: Track = None, resume: bool = False, overwrite: bool = False, **fields: Any) -> Study:
    """Run a study from a recipe (`motorlab run RECIPE`): its steps, table, findings and report.

    Args:
        recipe: a bundled recipe's name ("pendulum", "sar-hand-quick", "reacher-quick"; see
            `motorlab recipes`) or a TOML file.
        out: the study folder (default `runs/<recipe>-<time>`). Running again into the same folder
            keeps the steps that finished with the same settings; a finished study needs `resume`.
        resume: run again into a finished study's folder, keeping the steps that finished with the
            same settings (`motorlab run --resume`).
        overwrite: replace the study in `out` whole (`--overwrite`).
        backend: where a train step's seeds run: "local" (processes here) or "ray".
        max_parallel: seeds trained at once.
        parallel_steps: independent train steps run at once.
        **fields: fields of the recipe to set (`motorlab run --set KEY=VALUE`): FIELD for every step
            that has it, `**{"STEP.FIELD": value}` for one step, or one of the recipe's inputs
            (`run_recipe("sar-legs-published", sar="sar.npz")`).

    Returns:
        The study: `.table`, `.summary` (`"<step>.<key>"`), `.steps` (each step's `Result`),
        `.report()`; in Jupyter its findings and figures.
    """
    from motorlab.recipes import load_recipe
    from motorlab.studies import Execution, run_study

    block = folders(resume, overwrite)
    study = load_recipe(str(recipe), {k: path_of(v) for k, v in fields.items()})  # a Path or a Result: its path
    with trackers.tracking(track), block:
        summary = run_study(study, Path(out) if out is not None else None, console=console(),
                            execution=Execution(backend, address, max_parallel, parallel_steps))
    return Study(summary["study_dir"])


@api_function
def step(command: str, **fields: Any) -> StepTarget:
    """What a sweep or a search repeats: a step kind and its settings, as keyword arguments named as the
    command's options (None: the default). Judged now by the kind's settings model, as the CLI judges them.

        motorlab.sweep(motorlab.step("train", env="InvertedPendulum-v5", preset="fast", until_solved=True),
                       seeds=5, grid={"lr": [3e-4, 1e-3]})

    Args:
        command: the command, as the CLI names it: "train", "evaluate", "mpc", "dynamics fit", ...
        **fields: its settings (not the seed: the sweep sets it), e.g. `env`, `algo`, `timesteps`;
            `hyperparams={...}` for train's SB3 keyword arguments (`--set`).

    Returns:
        The target, for `sweep` and `tune`; `.text` is its command line.
    """
    return step_target(command, "sweep", **{k: path_of(v) for k, v in fields.items()})


@api_function
def recipe(recipe: str | Path, **fields: Any) -> RecipeTarget:
    """What a sweep or a search repeats: a whole study, a bundled recipe's name or a TOML file, with fields
    set in every trial as `run_recipe` sets them (FIELD, `**{"STEP.FIELD": value}` or an input).

        motorlab.sweep(motorlab.recipe("pendulum"), seeds=3, grid={"ppo.timesteps": [50_000, 100_000]})
    """
    return recipe_target(recipe, **{k: path_of(v) for k, v in fields.items()})


@api_function
def sweep(target: str | Path | Target, seeds: int | list[int] | None = None,
          grid: list[str] | dict[str, list[Any]] | None = None, *, backend: str | None = None,
          address: str | None = None, max_parallel: int | None = None, out: str | Path | None = None,
          track: Track = None, resume: bool = False, overwrite: bool = False) -> Sweep:
    """Run a command or a study for several seeds and settings, then aggregate with rliable
    (`motorlab sweep`): IQMs with 95% CIs, probabilities of improvement, performance profiles.

    The settings are `motorlab sweep`'s own (its settings model checks them and gives every default: None
    here is that default, `motorlab sweep --help` lists them), and it runs as the command does.

    Args:
        target: `step(...)` or `recipe(...)`; or, as the command line gives it, a motorlab command line
            ("train InvertedPendulum-v5 --preset fast --until-solved") or a recipe's name or file.
        seeds: seeds per setting (0..N-1), or the seeds themselves.
        grid: settings to cross, {"lr": [3e-4, 1e-3], "n_envs": [1, 2]}: each value as it is (numbers stay
            numbers, text is read as the command line reads it); or the command line's ["lr=3e-4,1e-3"].
        backend: "local" (a pool of processes) or "ray" (a cluster at `address`).
        resume: run again into a finished sweep's `out`, keeping its finished trials.
        overwrite: replace the sweep in `out` whole.

    Returns:
        The sweep: `.aggregate`, `.table`, `.summary`, `.report()`.
    """
    from motorlab.sweeps.sweep_command import SWEEP

    given = {"seeds": seeds} if not isinstance(seeds, list) else {}
    how = SWEEP.how(out=out, track=track, resume=resume, overwrite=overwrite)
    settings = SWEEP.make(how, target=str(target) if isinstance(target, Path) else target, grid=grid,
                          backend=backend, address=address, max_parallel=max_parallel, **given)
    if isinstance(seeds, list):  # the seeds themselves (the command line counts them: 0..N-1)
        if not seeds or any(isinstance(x, bool) or not isinstance(x, int) or x < 0 for x in seeds) \
                or len(set(seeds)) != len(seeds):
            raise MotorlabError(f"seeds {seeds!r}: give a count or a list of distinct non-negative integers.")
        settings = settings.model_copy(update={"seeds": seeds})
    summary = SWEEP.invoke(settings, how, console=console())
    return Sweep(summary["sweep_dir"])


@api_function
def tune(target: str | Path | Target, space: list[str] | dict[str, Any], *, trials: int | None = None,
         seeds: int | None = None, objective: str | None = None, direction: str | None = None,
         out: str | Path | None = None, storage: str | None = None, study_name: str | None = None,
         sampler: str | None = None, sampler_seed: int | None = None, pruner: str | None = None,
         prune_startup: int | None = None, report_every: int | None = None, fresh_seeds: int | None = None,
         max_parallel: int | None = None, backend: str | None = None, address: str | None = None,
         track: Track = None, resume: bool = False, overwrite: bool = False) -> Tune:
    """Search settings with Optuna, each trial judged by the IQM of `objective` over `seeds` seeds
    (`motorlab tune`); the best settings are re-run on fresh seeds.

    The settings are `motorlab tune`'s own (its settings model checks them and gives every default: None
    here is that default, e.g. 20 trials of 3 seeds judged by steps_to_success; `motorlab tune --help`
    lists them all), and it runs as the command does.

    Args:
        target: `step(...)` or `recipe(...)`; or, as the command line gives it, a motorlab command line in
            quotes ("train InvertedPendulum-v5 --timesteps 50000 --until-solved") or a recipe.
        space: what to search, {"lr": optuna.distributions.FloatDistribution(1e-5, 1e-2, log=True),
            "n_steps": optuna.distributions.CategoricalDistribution([256, 512])}, or as text
            {"lr": "loguniform:1e-5,1e-2"} / ["lr=loguniform:1e-5,1e-2"] (loguniform, uniform, int or choice).
        objective: steps_to_success, final_return, success_rate, or any summary number
            (a study's: "STEP.METRIC").
        out: the search's folder; the same `out` resumes an unfinished search.
        resume: go on with a finished search in `out` (e.g. with more `trials`).
        overwrite: replace the search's folder whole (a study in an external `storage` stays there).

    Returns:
        The search: `.best` (best.toml), `.trials`, `.summary` (with the fresh seeds' numbers).
    """
    from motorlab.tuning.tune_command import TUNE

    how = TUNE.how(out=out, track=track, resume=resume, overwrite=overwrite)
    settings = TUNE.make(how, target=str(target) if isinstance(target, Path) else target, space=space, trials=trials,
                         seeds=seeds, objective=objective, direction=direction, storage=storage,
                         study_name=study_name, sampler=sampler, sampler_seed=sampler_seed, pruner=pruner,
                         prune_startup=prune_startup, report_every=report_every, fresh_seeds=fresh_seeds,
                         max_parallel=max_parallel, backend=backend, address=address)
    summary = TUNE.invoke(settings, how, console=console())
    return Tune(summary["tune_dir"])
