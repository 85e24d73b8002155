"""What a search leaves in its folder: trials.csv, the table, best.toml, plots and summary.json."""

from __future__ import annotations

import csv
import io
import json
import shlex
import tomllib
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, get_args

import optuna
import tomli_w
from optuna.trial import FrozenTrial, TrialState

from motorlab.errors import mask_secrets
from motorlab.intervals import across_seeds
from motorlab.rl.config import TrainConfig
from motorlab.runs import atomic_write_text, write_summary
from motorlab.stats import Score
from motorlab.tuning.objective import Objective
from motorlab.tuning.space import Dist


@dataclass(frozen=True)
class Fresh:
    """The best settings re-run on seeds the search never used."""

    seeds: list[int]
    scores: list[Score]  # per seed: (value, censored: steps to success of a seed that never solved)
    objective: Objective

    @property
    def values(self) -> list[float]:
        return [v for v, _ in self.scores]

    @property
    def text(self) -> str:
        """What the seeds give together, with an interval only where the seeds allow one."""
        if self.objective.censors:
            return self.objective.describe(self.scores, number)
        return across_seeds(self.values).text(number)

    def to_summary(self) -> dict[str, Any]:
        """summary.json's fresh_* keys. Steps to success: k of n solved with its Wilson interval and
        the censored median with its bootstrap interval from 5 seeds (fresh_median_ci); otherwise
        the IQM from 4 seeds (else the mean), its 95% CI from 5 (fresh_ci None below), and the
        seeds' range (fresh_range); fresh_ci_method says what the shown interval is, or why none."""
        out = {"fresh_seeds": self.seeds, "fresh_values": self.values, "fresh_censored": [c for _, c in self.scores],
               "fresh_text": self.text}
        if self.objective.censors:
            reached = self.objective.reached(self.scores)
            # no interval for the restricted mean; the median's is fresh_median_ci
            return {**out, "fresh_value": self.objective.combine(self.values),
                    "fresh_statistic": self.objective.statistic(len(self.scores)), "fresh_ci": None,
                    "fresh_ci_method": "no interval for the restricted mean: unsolved seeds censored at their budgets",
                    "fresh_solved": reached.solved, "fresh_solved_ci": list(reached.solved_ci),
                    "fresh_median": reached.median, "fresh_median_above": reached.median_above,
                    "fresh_median_ci": reached.median_ci.to_json() if reached.median_ci else None,
                    "fresh_median_ci_method": reached.median_ci_method}
        s = across_seeds(self.values)
        return {**out, "fresh_value": s.value, "fresh_statistic": s.statistic,
                "fresh_ci": list(s.ci) if s.ci else None, "fresh_range": list(s.range) if s.range else None,
                "fresh_ci_method": s.method}


def keep_seed_scores(trial: optuna.Trial | FrozenTrial, scores: list[Score]) -> None:
    """A finished trial's per-seed numbers, and which are censored, in the study's database."""
    trial.set_user_attr("seed_values", [v for v, _ in scores])
    trial.set_user_attr("seed_censored", [c for _, c in scores])


def seed_scores(trial: FrozenTrial) -> list[Score]:
    """A trial's per-seed numbers (a trial from before censored flags were kept: none censored)."""
    values = trial.user_attrs.get("seed_values", [])
    censored = trial.user_attrs.get("seed_censored") or [False] * len(values)
    return [(float(v), bool(c)) for v, c in zip(values, censored)]


def seeds_text(objective: Objective, scores: list[Score]) -> str:
    """Each seed's number, a censored one as "> budget"."""
    return ", ".join(objective.seed_text(s, number) for s in scores)


def trial_line(objective: Objective, scores: list[Score]) -> str:
    """A finished trial as the terminal says it."""
    return f"{objective.key} {objective.describe(scores, number)} (seeds: {seeds_text(objective, scores)})"


def shown_trials(study: optuna.Study) -> list[FrozenTrial]:
    """Every trial but those that gave way to another process before running anything."""
    return [t for t in study.get_trials(deepcopy=False) if not t.user_attrs.get("gave_way")]


def write_trials_csv(trials: list[FrozenTrial], space: dict[str, Dist], path: Path) -> None:
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(["number", "state", *space, "value", "seed_values", "seed_censored", "env_steps", "env_steps_saved"])
    for t in trials:
        scores = seed_scores(t)
        writer.writerow([t.number, t.state.name, *(t.params.get(k, "") for k in space),
                         "" if t.value is None else t.value, " ".join(f"{v:g}" for v, _ in scores),
                         " ".join(str(int(c)) for _, c in scores),
                         t.user_attrs.get("env_steps", ""), t.user_attrs.get("env_steps_saved", "")])
    atomic_write_text(path, mask_secrets(buf.getvalue()))


COLUMNS = ["trial", "state", "settings", "value", "per seed", "env steps"]


def number(v: float) -> str:
    """An objective's value as people read it: 16,384 (not 1.638e+04), 812.3, 0.9667."""
    return f"{v:,.0f}" if abs(v) >= 1000 else f"{v:.4g}"


def table_rows(trials: list[FrozenTrial], space: dict[str, Dist], best: FrozenTrial | None,
               fresh: Fresh | None, objective: Objective) -> list[list[str]]:
    rows = []
    for t in trials:
        settings = ", ".join(f"{k}={t.params[k]:.4g}" if isinstance(t.params.get(k), float) else f"{k}={t.params.get(k)}"
                             for k in space if k in t.params)
        mark = " (best)" if best is not None and t.number == best.number else ""
        rows.append([f"{t.number}{mark}", t.state.name.lower(), settings,
                     "" if t.value is None else number(t.value), seeds_text(objective, seed_scores(t)),
                     f"{t.user_attrs.get('env_steps', 0):,}"])
    if best is not None and fresh is not None:
        rows.append([f"{best.number} on fresh seeds", "complete", f"seeds {fresh.seeds[0]}..{fresh.seeds[-1]}",
                     fresh.text, seeds_text(objective, fresh.scores), ""])
    return rows


def preset_fields(settings: dict[str, str], space: dict[str, Dist], options: set[str] | None) -> dict[str, Any]:
    """The best settings as TrainConfig fields (a preset file): options by their field names,
    `--set` hyperparameters in [hyperparams]; with `options` None (a recipe) STEP.FIELD keys
    in a table per step."""
    out: dict[str, Any] = {}
    for key, text in settings.items():
        value = _value(text)
        dist = space[key]
        if options is None:
            step, dot, name = key.rpartition(".")
            (out.setdefault(step, {}) if dot else out)[name] = value
        elif dist.is_hyperparam or dist.name.replace("-", "_") not in options:
            out.setdefault("hyperparams", {})[dist.name] = value
        else:
            name = dist.name.replace("-", "_")
            out[name] = text if _text_field(name) else value  # lr = "3e-4": a schedule, written as text
    return out


def _text_field(name: str) -> bool:
    """A TrainConfig field that holds text only (schedules such as lr and clip_range)."""
    field = TrainConfig.model_fields.get(name)
    return field is not None and set(get_args(field.annotation)) <= {str, type(None)} and field.annotation is not None \
        and str in get_args(field.annotation)


def _value(text: str) -> Any:
    """A sampled value as TOML should hold it: JSON numbers, booleans, lists; else the text."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        return text
    return value if value is not None else text


def write_best_toml(path: Path, fields: dict[str, Any], header: list[str]) -> None:
    """The preset file, credentials masked (its header quotes the target's command line); the fields masked
    as data, so that the TOML stays valid."""
    comments = "".join(f"# {line}\n" for line in mask_secrets(header))
    atomic_write_text(path, comments + tomli_w.dumps(mask_secrets(fields)))


def write_best_recipe(path: Path, trial_dir: Path, header: list[str]) -> None:
    """The recipe variant the best trial ran for its first seed (its settings applied, every step's
    seed that seed), with the header and how to run it."""
    first = min((trial_dir / "recipes").glob("*-seed*.toml"), key=lambda p: int(p.stem.rpartition("-seed")[2]))
    lines = [*header, f"the recipe as trial {trial_dir.name} ran it on its first seed: motorlab run {path.name}"]
    recipe = tomli_w.dumps(mask_secrets(tomllib.loads(first.read_text())))  # masked as data: valid TOML
    atomic_write_text(path, "".join(f"# {line}\n" for line in mask_secrets(lines)) + recipe)


def reproduce_line(target: str, best_toml: Path, seed: int) -> str:
    return f"motorlab {target} --preset-file {shlex.quote(str(best_toml))} --seed {seed}"


def write_plots(study: optuna.Study, space: dict[str, Dist], plots: Path, title: str) -> list[Path]:
    """Optimization history, parameter importances (two or more keys, enough trials) and one
    slice plot per key, each with its caption inside the PNG (motorlab's save_figure)."""
    from motorlab.report.plots import save_figure  # noqa: I001 (first: it picks the files-only backend)
    import matplotlib.pyplot as plt
    from optuna.visualization import matplotlib as ovm

    warnings.filterwarnings("ignore", category=UserWarning, module="optuna")  # flat axes of one-valued keys
    done = [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]
    if not done:
        return []
    written = []

    def save(ax_or_axes, name: str, caption: str) -> None:
        ax = ax_or_axes.ravel()[0] if hasattr(ax_or_axes, "ravel") else ax_or_axes
        fig = ax.figure
        fig.suptitle(title, fontsize=9)
        if (p := save_figure(fig, plots / name, caption)) is not None:
            written.append(p)
        plt.close("all")

    save(ovm.plot_optimization_history(study), "history.png", "Objective of each trial and the best so far")
    if len(space) >= 2 and len(done) >= 4:
        try:
            save(ovm.plot_param_importances(study), "importances.png", "How much each setting explains the objective "
                 "(fANOVA)")
        except (RuntimeError, ValueError, ZeroDivisionError):
            plt.close("all")  # too few distinct values to rank the settings
    for key in space:
        safe = "".join(c if c.isalnum() or c in "._-" else "_" for c in key)
        save(ovm.plot_slice(study, params=[key]), f"slice-{safe}.png", f"Objective against {key}, one dot per trial")
    return written


def write_tune_summary(out: Path, summary: dict[str, Any]) -> None:
    write_summary(out, mask_secrets(summary))
