"""Studies, sweeps and searches from Python: `motorlab run`, `motorlab sweep`, `motorlab tune`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from motorlab import trackers
from motorlab.api.checks import api_function
from motorlab.api.steps import Track, console, folders
from motorlab.api.views import Study, Sweep, Tune


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
    study = load_recipe(str(recipe), fields)
    with trackers.tracking(track), block:
        summary = run_study(study, Path(out) if out is not None else None, console=console(),
                            execution=Execution(backend, address, max_parallel, parallel_steps))
    return Study(summary["study_dir"])


@api_function
def sweep(target: str | Path, seeds: int | list[int] = 5, grid: list[str] | dict[str, list[Any]] | None = None, *,
          backend: str = "local", address: str | None = None, max_parallel: int | None = None,
          out: str | Path | None = None, track: Track = None, resume: bool = False, overwrite: bool = False) -> Sweep:
    """Run a command or a study for several seeds and settings, then aggregate with rliable
    (`motorlab sweep`): IQMs with 95% CIs, probabilities of improvement, performance profiles.

    Args:
        target: a motorlab command line ("train InvertedPendulum-v5 --preset fast --until-solved")
            or a recipe (each trial runs the whole study).
        seeds: seeds per setting (0..N-1), or the seeds themselves.
        grid: settings to cross: ["lr=3e-4,1e-3", "n_envs=1,2"] or {"lr": [3e-4, 1e-3]}.
        backend: "local" (a pool of processes) or "ray" (a cluster at `address`).
        resume: run again into a finished sweep's `out`, keeping its finished trials.
        overwrite: replace the sweep in `out` whole.

    Returns:
        The sweep: `.aggregate`, `.table`, `.summary`, `.report()`.
    """
    from motorlab.sweeps.sweep import run_sweep

    with trackers.tracking(track), folders(resume, overwrite):
        summary = run_sweep(str(target), seeds, _pairs(grid), backend, address, max_parallel,
                            Path(out) if out is not None else None, console=console())
    return Sweep(summary["sweep_dir"])


@api_function
def tune(target: str | Path, space: list[str] | dict[str, str], *, trials: int = 20, seeds: int = 3,
         objective: str = "steps_to_success", direction: str | None = None, out: str | Path | None = None,
         storage: str | None = None, study_name: str | None = None, sampler: str = "tpe",
         sampler_seed: int | None = None, pruner: str = "median", prune_startup: int = 5, report_every: int = 1000,
         fresh_seeds: int | None = None, max_parallel: int | None = None, backend: str = "local",
         address: str | None = None, track: Track = None, resume: bool = False, overwrite: bool = False) -> Tune:
    """Search settings with Optuna, each trial judged by the IQM of `objective` over `seeds` seeds
    (`motorlab tune`); the best settings are re-run on fresh seeds.

    Args:
        target: a motorlab command line in quotes ("train InvertedPendulum-v5 --timesteps 50000
            --until-solved") or a recipe.
        space: what to search: ["lr=loguniform:1e-5,1e-2", "n_steps=choice:256,512"] or
            {"lr": "loguniform:1e-5,1e-2"} (loguniform, uniform, int or choice).
        objective: steps_to_success, final_return, success_rate, or any summary number
            (a study's: "STEP.METRIC").
        out: the search's folder; the same `out` resumes an unfinished search.
        resume: go on with a finished search in `out` (e.g. with more `trials`).
        overwrite: replace the search's folder whole (a study in an external `storage` stays there).

    Returns:
        The search: `.best` (best.toml), `.trials`, `.summary` (with the fresh seeds' numbers).
    """
    from motorlab.tuning.tune import make_spec, run_tune

    spec = make_spec(str(target), _pairs(space), trials, seeds, objective, direction,
                     Path(out) if out is not None else None, storage, study_name, sampler, pruner, prune_startup,
                     report_every, max_parallel, fresh_seeds, backend=backend, address=address,
                     sampler_seed=sampler_seed)
    with trackers.tracking(track), folders(resume, overwrite):  # run_tune is the parent run itself
        summary = run_tune(spec, console=console())
    return Tune(summary["tune_dir"])


def _pairs(values: list[str] | dict[str, Any] | None) -> list[str] | None:
    """KEY=VALUE strings from a dict, as the command line gives them: a list's values joined with
    commas, or with | where one holds a comma itself ("linear:3e-4,0")."""
    if values is None or isinstance(values, list):
        return values
    pairs = []
    for key, value in values.items():
        if isinstance(value, str):
            pairs.append(f"{key}={value}")
        else:
            texts = [str(v) for v in value]
            pairs.append(f"{key}={('|' if any(',' in t for t in texts) else ',').join(texts)}")
    return pairs
