"""What a step kind is made of: settings, references, a run, and its row in a study's table.

A step kind (train, evaluate, collect, fit, mpc, ...) is one object in one file of `motorlab/kinds/`,
above the domain code it calls, e.g. `motorlab/kinds/dynamics.py`. It holds:

- `Settings`: a pydantic model, the one source of defaults, validation and help text;
- `refs`: which of its fields may name an earlier step of a recipe ("@step"), and what that
  step must provide (an `Artifact`: a policy, activations, a SAR, transitions, a model);
- `run(settings, out) -> Summary`: the work, written to a run folder; `Summary` is typed
  and is what summary.json holds;
- what a study shows of it: `describe` (the "what" column), `headline` (the numbers it keeps)
  and `metrics` (those numbers as people read them: label, unit, format; see
  motorlab.report.results), and which of them are its findings by default.

The registry (`motorlab.kinds`) lists the kinds. The CLI, recipes, studies, sweeps and the
Python API all go through these objects, so adding a capability is one new file.

A kind's module imports its settings' needs at the top and the domain code that runs it (torch,
matplotlib, rollouts) inside `run` and the other methods that use it: the CLI reads every
kind's settings when it starts, and should start in a fraction of a second.

Experiment tracking (motorlab.trackers, `--track`): every kind's `run` is wrapped, once, where
the subclass defines it, so that a run is one tracked run whoever calls it (the CLI, a study, a
sweep trial, a script) and no kind has to say so. The tracked run starts when the run folder is
made (`start`, or the train kind's own folder), gets the scalars its TensorBoard writers get,
then its summary and files when `run` returns; it ends FAILED when `run` raises.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import statistics
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar, get_args, get_origin

from rich.console import Console

from motorlab import claims, trackers
from motorlab.command import Command, Tracked
from motorlab.envs import early_end_label, fold_env
from motorlab.errors import MotorlabError
from motorlab.faults import write_faults_log
from motorlab.intervals import across_seeds
from motorlab.report.results import Metric, Number, RunResults, write_run_results
from motorlab.runs import (
    FolderMode,
    prepare_run_dir,
    read_text_file,
    refuse_finished,
    run_folders,
    write_config,
    write_summary,
)
from motorlab.settings import Settings, Summary


@dataclass(frozen=True)
class Artifact:
    """What a step's run folder provides to later steps: `file` inside it, or the folder itself."""

    name: str
    file: str | None = None


@dataclass(frozen=True)
class Ref:
    """A settings field that may name earlier steps ("@step") providing one of `accepts`."""

    field: str
    accepts: tuple[str, ...]


@dataclass(frozen=True)
class Scores:
    """Evaluation numbers of one run, for the study's return and success columns."""

    return_mean: float | None
    return_std: float | None
    return_min: float | None
    success_rate: float | None
    episodes: int
    episode_length_mean: float | None = None
    falls: int | None = None


S = TypeVar("S", bound=Settings)
R = TypeVar("R", bound=Summary)


class StepKind(Command[S], Generic[S, R]):
    """One kind of step: a command (motorlab.command) that writes one run folder and can be a step
    of a recipe. Subclasses name their settings and summary types as the generic's parameters
    (`class FitKind(StepKind[FitSettings, FitSummary])`), set the class attributes and implement
    `run` (and `report`, what the command line prints of its summary)."""

    # the CLI command that runs it (default: the name, "dynamics-fit" -> "dynamics fit"); None: recipes only
    summary: ClassVar[type[Summary]]
    invocation = Tracked
    refs: ClassVar[tuple[Ref, ...]] = ()
    provides: ClassVar[Artifact | None] = None
    # a study draws its returns figure from these kinds
    scored: ClassVar[bool] = False
    # training: a recipe's `seeds = N` runs it once per seed, as processes (as jobs: motorlab.jobs),
    # it may run beside other steps, and a study charts its steps to success
    trains: ClassVar[bool] = False
    # a step of this kind that names a step trained with several seeds runs once per seed
    per_seed: ClassVar[bool] = False
    # the summary keys a study keeps of it (None: all of them); see `headline`
    headline_keys: ClassVar[tuple[str, ...] | None] = None
    # its headline numbers as reports and table.txt show them, in this order (see `numbers`)
    metrics: ClassVar[tuple[Metric, ...]] = ()
    # the keys of those a study's findings show by default, when the recipe names none
    findings: ClassVar[tuple[str, ...]] = ()
    # figures of its run folder a study's report shows beside its own (paths inside the folder)
    key_figures: ClassVar[tuple[str, ...]] = ()
    # the table's "what" and "notes" cells, formatted with the settings and the headline (kinds
    # whose cells need more than a format override `describe` and `notes`)
    what: ClassVar[str | None] = None
    note: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for base in getattr(cls, "__orig_bases__", ()):
            if get_origin(base) is StepKind:
                cls.settings, cls.summary = get_args(base)
        if "run" in cls.__dict__:
            cls.run = _tracked(cls.__dict__["run"])

    def run(self, settings: S, out: Path | None = None, console: Console | None = None, progress: bool = True) -> R:
        """Run the step into the run folder `out` (default: runs/<kind>-<time>); `console` gets its
        tables, `progress` says whether to show progress bars. A kind that can continue an
        interrupted run (`can_resume`) also takes `resume=True`."""
        raise NotImplementedError

    def perform(self, settings: S, out: Path | None = None, *, folders: FolderMode | None = None,
                track: list[str] | str | None = None, resume: bool = False, console: Console | None = None,
                progress: bool = True) -> R:
        """The one door every caller runs a step through: the CLI and a worker (`invoke`), a study's steps,
        the Python API. Under the run-folder mode `folders` (motorlab.runs.run_folders; None: the enclosing
        one, a study's) and the trackers `track` (None: as an enclosing block says), `run` checks its inputs,
        opens the run folder (`start`, locked and tracked), works, and writes it whole (`finish`).
        `resume`: continue the interrupted run in `out` (a kind that `can_resume`)."""
        folder_mode = run_folders(folders) if folders is not None else contextlib.nullcontext()
        with trackers.tracking(track), folder_mode:
            if resume:
                return self.run(settings, out, console=console, progress=progress, resume=True)  # type: ignore[call-arg]
            return self.run(settings, out, console=console, progress=progress)

    def invoke(self, settings: S, how: Any, console: Console | None = None, progress: bool = True) -> R:
        """The command line's and a worker's way in: `execute`, which goes through `perform` with the
        invocation's folder mode and trackers."""
        return self.execute(settings, how, console, progress)

    def execute(self, settings: S, how: Tracked, console: Console | None, progress: bool) -> R:
        return self.perform(settings, how.out, folders=how.mode(), track=how.track, console=console, progress=progress)

    def report(self, result: R, settings: S, console: Console) -> None:
        console.print(f"written: {result.run_dir}/summary.json")
        warn_faults(result)

    def check(self, settings: S) -> None:
        """Checks a recipe runs before any step does (e.g. that the env exists)."""

    def inputs(self, settings: S) -> list[Path]:
        """The folders this run reads, from its reference fields (a file stands for its folder;
        built-in names such as "pid" are no folders)."""
        folders = []
        for ref in self.refs:
            value = getattr(settings, ref.field, None)
            if value is None and hasattr(settings, "env"):  # flat env settings (sar) live in settings.env
                value = getattr(settings.env, ref.field, None)
            for text in _strings(value):
                path = Path(text)
                if path.exists():
                    folders.append(path if path.is_dir() else path.parent)
        return folders

    def prepare(self, fields: dict[str, Any], referenced: dict[str, Settings]) -> dict[str, Any]:
        """A recipe step's fields before validation, given the settings of the steps it names."""
        return fields

    def describe(self, settings: S, copies: int = 1) -> str:
        """The "what" column of a study's table (`copies`: seeds it runs for)."""
        return self.what.format(**settings.model_dump()) if self.what else self.name

    def headline(self, summary: R) -> dict[str, Any]:
        """The numbers a study keeps of this step ("<step>.<key>" in its summary.json)."""
        keys = summary.keys()
        return keys if self.headline_keys is None else {k: keys.get(k) for k in self.headline_keys}

    def aggregate(self, summaries: list[R]) -> dict[str, Any]:
        """The headline of several runs of this step (one per seed)."""
        if len(summaries) == 1:
            return self.headline(summaries[0])
        raise NotImplementedError(f"{self.name} steps run once")

    def scores(self, summary: R) -> Scores | None:
        """The run's evaluation numbers, where it has them."""
        return None

    def numbers(self, settings: S, headline: dict[str, Any]) -> list[Number]:
        """Its headline numbers as people read them (those it has values for), from `metrics`."""
        return [n for m in self.metrics if (n := m.number(headline)) is not None]

    def notes(self, settings: S, headline: dict[str, Any]) -> str:
        """The table's notes cell: what the numbers do not say."""
        return self.note.format(**headline)

    def metric(self, key: str) -> Metric:
        """How the headline number `key` is shown (a plain number where the kind names none)."""
        return next((m for m in self.metrics if m.key == key), None) or Metric(key, key.replace("_", " "))

    def default_findings(self, settings: S, headline: dict[str, Any]) -> list[str]:
        """The headline keys a study's findings show of this step when the recipe names none."""
        return [k for k in self.findings if headline.get(k) is not None]

    def seed_values(self, runs: list[tuple[str, R]], key: str) -> list[tuple[str, Any]]:
        """Each seed's value of the headline number `key`, from its runs (label, summary)."""
        return [(label, self.headline(s).get(key)) for label, s in runs]

    def results(self, settings: S, summary: R) -> RunResults:
        """results.json of one run: its headline numbers as shown."""
        return RunResults(self.name, self.numbers(settings, self.headline(summary)))

    def figures(self, run_dir: Path) -> None:
        """Figures a study draws of a finished run (in its main thread: matplotlib is not
        thread-safe, and training steps may run in the background)."""

    def progress(self, settings: S, run_dir: Path) -> tuple[int, int]:
        """(done, total) of a run going on in another process, for progress bars."""
        return 0, 1

    def fields_for(self, how: Any, given: dict[str, Any]) -> dict[str, Any]:
        """`given` over the config.toml its invocation's --config names (a kind whose invocation
        has one, as train's does), merged before anything is validated: `train --config SAC_RUN
        --her` is judged as SAC with HER."""
        config = getattr(how, "config", None)
        return given if config is None else self.with_config(Path(config), given)

    def with_config(self, config: Path, fields: dict[str, Any]) -> dict[str, Any]:
        """A run's config.toml (`--config`: repeat a run, or run one a study planned) with `fields` on
        top; env settings, flat or in [env], merged key by key.

        Raises:
            MotorlabError: the file cannot be read as TOML.
        """
        base = read_text_file(Path(config), tomllib.loads, "TOML", f"give the config.toml of a motorlab {self.name} run.")
        own = frozenset(self.settings.model_fields) - {"env"}  # a kind's own field (mpc's planner --reward) stays its own
        given = fold_env(fields, own) if "env" in self.settings.model_fields else dict(fields)
        merged = {**base, **{k: v for k, v in given.items() if k != "env"}}
        if "env" in given or "env" in base:
            merged["env"] = {**fold_env(base, own).get("env", {}), **given.get("env", {})}
        return merged

    # ---- what orchestration (studies, sweeps, searches) asks of a kind, never by a field's name ----------

    SEED: ClassVar[str] = "seed"  # the settings field a kind's runs take their seed from, where they have one

    @classmethod
    def takes_seed(cls) -> bool:
        """Its runs take a seed (a sweep repeats them over seeds, a study's `seeds = N` fans them out)."""
        return cls.SEED in cls.settings.model_fields

    def seeded(self, settings: S, seed: int) -> S:
        """`settings` for the run of seed `seed`."""
        return settings.model_copy(update={self.SEED: seed})

    def with_seed(self, fields: dict[str, Any], seed: int) -> dict[str, Any]:
        """Settings fields (before validation) for the run of seed `seed`."""
        return {**fields, self.SEED: seed}

    BUDGET: ClassVar[str | None] = None  # the settings field holding the env steps a run may take, where it has one

    def planned_steps(self, settings: S) -> int | None:
        """The env steps a run of these settings may take (its budget); None for a kind without one."""
        return _positive_int(getattr(settings, self.BUDGET)) if self.BUDGET else None

    def planned_steps_of(self, config: dict[str, Any]) -> int | None:
        """The same, read from a run folder's config.toml (the settings it was started with)."""
        return _positive_int(config.get(self.BUDGET)) if self.BUDGET else None

    def stops_early(self, settings: S) -> bool:
        """A run may end before its budget once it has solved its task (a study charts its steps to success)."""
        return False

    def budget(self, headline: dict[str, Any]) -> int | None:
        """The env steps a finished run was allowed, from its headline (a seed that never solved is censored
        there); None for a kind with no such budget."""
        return None

    def can_resume(self, run_dir: Path) -> bool:
        """An interrupted run in `run_dir` can be continued (`run(..., resume=True)`), not redone."""
        return False

    def warm_up(self) -> None:
        """Import, in the calling thread, what this kind imports when it runs in the background. A
        study calls it before it starts steps in threads: two threads importing one package at once
        can fail where the package imports itself in a circle (SB3 does)."""

    # ---- the ending every run shares ------------------------------------------------------

    def refuse_finished_out(self, out: Path | None) -> None:
        """Refuse an --out this run may not write (a finished run, another kind's, a folder that is not
        motorlab's: see `refuse_finished`) before the work: a kind calls it once its inputs are checked
        (so an input mistake is still named first) and before its episodes. `start` checks again, as
        the folder's locked writer; this one saves the work a refusal would waste."""
        if out is not None:
            refuse_finished(Path(out), kind=self.name)

    def start(self, out: Path | None) -> Path:
        """The run folder, created, marked as this kind's and unfinished, and locked until `run` returns
        (call once the settings are checked); a tracked run starts here."""
        run_dir = prepare_run_dir(out, self.name)
        trackers.folder_ready(run_dir)
        return run_dir

    def finish(self, run_dir: Path, settings: S, summary: R, faults: list[str] | None = None) -> R:
        """config.toml, faults.log (where episodes ran), results.json and summary.json, the last file written."""
        if faults is not None:
            write_faults_log(run_dir, faults)
        write_config(run_dir, settings.config())
        write_run_results(run_dir, self.results(settings, summary))
        write_summary(run_dir, summary.keys())
        summary.run_dir = Path(run_dir)
        return summary


def warn_faults(summary: Summary) -> None:
    """One line on stderr when episodes ended on a numerical fault (they are counted and listed, not
    fatal). The planner's rejected candidates are warned about by the planning kinds themselves."""
    n = getattr(summary, "episode_faults", None)
    if n is None:
        n = getattr(summary, "numerical_faults", 0) or 0
    if n:
        Console(stderr=True).print(
            f"[yellow]warning[/yellow]: {n} episode{'s' if n > 1 else ''} ended on a numerical fault (NaN/Inf or a "
            f"diverging simulation); reasons in {summary.run_dir}/faults.log", soft_wrap=True)


def _tracked(run):
    """A kind's `run` as one tracked run, when tracking is on (motorlab.trackers; else `run` itself
    does all, at the cost of one look at the environment)."""
    if getattr(run, "_motorlab_tracked", False):
        return run

    @functools.wraps(run)
    def tracked_run(self, settings, out=None, *args, **kwargs):
        if out is not None:
            refuse_input_folder(self, settings, Path(out))
        # the run folder's lock (motorlab.claims), taken when `start` makes it, is held to the run's end
        with claims.lock_scope(), trackers.step(self.name, settings) as tracked:
            summary = run(self, settings, out, *args, **kwargs)
            if tracked:
                tracked.done(summary.run_dir, summary.keys())
        return summary

    tracked_run._motorlab_tracked = True
    return tracked_run


def refuse_input_folder(kind: StepKind, settings: Settings, out: Path) -> None:
    """A step never writes into the folder it reads (`dynamics fit X --out X` would replace the
    collect run's config.toml and summary.json)."""
    target = out.resolve()
    for folder in kind.inputs(settings):
        if folder.resolve() == target:
            raise MotorlabError(f"--out {out} is the folder of this step's input; a step writes a folder of its "
                                "own: choose another --out.")


def _strings(value: Any) -> list[str]:
    """Every string in a field value (a string, a list, or a dict of lists)."""
    if isinstance(value, (str, Path)):
        return [str(value)]
    if isinstance(value, dict):
        value = list(value.values())
    if isinstance(value, (list, tuple)):
        return [s for v in value for s in _strings(v)]
    return []


def seeds_headline(all_scores: list[Scores]) -> dict[str, Any]:
    """The headline of a train or evaluate step run for several seeds: the mean over seeds (std
    across seeds), and from 4 seeds rliable's IQM of the return (below, it trims nothing: it is the
    mean), with a 95% bootstrap CI from 5 seeds where it has a width (`iqm_keys`)."""
    means = [s.return_mean for s in all_scores]
    out = {
        "seeds": len(all_scores),
        "return_mean": statistics.fmean(means),
        "return_std": statistics.stdev(means),
        "return_min": min(s.return_min for s in all_scores),
        "success_rate": _mean_of_known([s.success_rate for s in all_scores]),  # None: the env defines no success
        "episodes": sum(s.episodes for s in all_scores),
    }
    return {**out, **iqm_keys("return", means)}


def _mean_of_known(values: list[float | None]) -> float | None:
    known = [v for v in values if v is not None]
    return statistics.fmean(known) if known else None


def iqm_keys(name: str, values: list[float]) -> dict[str, float]:
    """Over seeds (motorlab.intervals): from MIN_SEEDS_FOR_IQM seeds "<name>_iqm", and from
    MIN_SEEDS_FOR_INTERVAL seeds its 95% CI "<name>_iqm_ci_low" and "_high" where it has a width.
    Below 5 seeds no "_ci_" keys (the seeds' range is no CI), so a headline number shown with
    "[low, high]" after it is always that 95% CI."""
    summary = across_seeds(values)
    statistic = "iqm" if summary.statistic == "IQM" else "mean"
    out = {f"{name}_iqm": summary.value} if statistic == "iqm" else {}
    if summary.ci:
        out.update({f"{name}_{statistic}_ci_low": summary.ci[0], f"{name}_{statistic}_ci_high": summary.ci[1]})
    return out


# Numbers of the kinds that evaluate a policy (train, evaluate): the same labels everywhere.
RETURN = Metric("return_mean", "return", "return", spread="return_std")
SCORED_METRICS = (
    RETURN,
    Metric("return_iqm", "return IQM (95% CI from 5 seeds)", "return"),  # its brackets: the CI (`iqm_keys`)
    Metric("return_min", "min return", "return"),
    Metric("success_rate", "success", "percent"),
    Metric("episode_length_mean", "mean length", "steps"),
    Metric("falls", "falls", "count", of="episodes"),
    Metric("seeds", "seeds", "count", setup=True),
    Metric("episodes", "evaluation episodes", "count", setup=True),
)


def scored_numbers(metrics: tuple[Metric, ...], h: dict[str, Any], env_id: str) -> list[Number]:
    """Numbers of an evaluated policy (the IQM with its CI where there are seeds), with episodes
    that ended early called falls only where the env defines a fall, and success named by what
    it is (h["success_by"]: '"solved" at the final step', "return ≥ 1000")."""
    by = h.get("success_by")

    def label(m: Metric) -> str:
        if m.key == "falls":
            return early_end_label(env_id)
        if by and m.key in ("success_rate", "train_success_rate_last100"):
            return f"{m.label[:-1]}, {by})" if m.label.endswith(")") else f"{m.label} ({by})"
        return m.label

    return [n for m in metrics if (n := dataclasses.replace(m, label=label(m)).number(h)) is not None]


def _positive_int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) and value > 0 else None
