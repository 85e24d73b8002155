"""The `robustness` step kind: policies evaluated across a grid of disturbances, as curves."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

from pydantic import Field, field_validator
from rich.console import Console
from rich.table import Table

from motorlab.envs import ENV_KEYS, EnvConfig, EnvSettings, given_env
from motorlab.report.results import Metric, Number, show
from motorlab.robustness_curves.grid import VARIABLES, parse_axes
from motorlab.settings import MAX_SEED, Summary
from motorlab.stepkind import Ref, StepKind, warn_faults


class RobustnessSettings(EnvSettings):
    """Evaluate policies across a grid of disturbances: one curve per policy and disturbance."""

    # flat env settings (push_body, delay_on, env_kwargs, ...) go into `env`, on top of each policy's own
    aliases: ClassVar[frozenset[str]] = frozenset(ENV_KEYS) - {"reward"}
    env_refused: ClassVar[dict[str, str]] = {
        "reward": "robustness reports the env's own return (evaluation applies no reward shaping); drop it."}
    policies: list[str] = Field(min_length=1, description="Policies to compare: run folders (one per seed of a "
                                "step: a band) or built-in controllers (pid, zero, random)")
    vary: list[str] = Field(min_length=1, description="A disturbance and its grid, KEY=START:STOP:N or "
                            "KEY=V1,V2,...; KEY: " + ", ".join(k.replace("_", "-") for k in VARIABLES)
                            + "; e.g. delay=0:0.3:7")
    episodes: int = Field(20, gt=0, description="Episodes per policy and grid value")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (episode i of every point resets with seed + i)")
    workers: int | None = Field(None, ge=1, description="Processes that step the envs (default: every core "
                                "when the work is large enough)")
    env: EnvConfig = Field(default_factory=EnvConfig, description="The env every policy is tested in, under "
                           "the grid's disturbance (e.g. push_body, delay_on, kwargs; id for built-in controllers): "
                           "the settings given only (model_fields_set); run folders keep their own env id, "
                           "arguments, history and synergies, not the disturbances they trained with")

    def config(self) -> dict[str, Any]:
        """config.toml: the env settings as given (those not given are each policy's own)."""
        data = self.model_dump()
        given = given_env(self.env)
        if given:
            data["env"] = given
        else:
            data.pop("env")
        return data

    @field_validator("vary")
    @classmethod
    def _check_vary(cls, v: list[str]) -> list[str]:
        parse_axes(v)
        return v


class RobustnessSummary(Summary):
    """Also "<policy>.<disturbance>.holds_from" and ".holds_to" (the widest range of grid values over
    which it holds; null: at none) for every policy and disturbance, and "curves"."""

    policies: list[str]
    vary: dict[str, list[float]]
    measure: str
    episodes: int
    seed: int
    numerical_faults: int


class RobustnessKind(StepKind[RobustnessSettings, RobustnessSummary]):
    """How far each policy holds as a disturbance grows: one curve per policy and disturbance.

    Evaluates every policy at every value of each --vary grid (one disturbance at a time, the
    others at the policy's own settings, the same reset seeds at every value); prints a table,
    writes curves.csv, summary.json and plots/robustness.png.

    Every policy meets the same env: the env options given here (e.g. --push-body pole for --vary
    push-force, --delay-on action for --vary delay; --env for built-in controllers, default the
    first run's) plus the grid's disturbance. Run folders keep their own env id, arguments, history
    and synergies, not the noise or delay they trained with.
    """

    name = "robustness"
    arguments = ("policies",)
    examples = (
        "motorlab robustness pid runs/ppo runs/ppo-history --vary delay=0:0.3:7 --episodes 20",
        "motorlab robustness runs/ppo --vary obs-noise=0:0.05:6 --vary latency=0:4:5",
        "motorlab robustness pid runs/ppo --vary push-force=0:40:5 --push-body pole --push-direction x",
    )
    refs = (Ref("policies", ("policy",)), Ref("sar", ("sar",)))
    key_figures = ("plots/robustness.png",)

    def check(self, settings: RobustnessSettings) -> None:
        parse_axes(settings.vary)

    def run(self, settings: RobustnessSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> RobustnessSummary:
        from motorlab.robustness_curves.curves import measure, subjects, write_points_csv
        from motorlab.robustness_curves.plots import robustness_plot

        axes = parse_axes(settings.vary)
        targets = subjects(settings.policies, settings.env)
        self.refuse_finished_out(out)
        curves = measure(targets, axes, settings.episodes, settings.seed, settings.workers, progress)
        run_dir = self.start(out)
        write_points_csv(run_dir / "curves.csv", curves)
        robustness_plot(curves, run_dir / "plots" / "robustness.png",
                        f"Robustness on {targets[0].env.id}: {settings.episodes} episodes per point")
        bands = {(g, a.key): curves.holds(g, a.key) for g in curves.groups for a in axes}
        holds = {f"{g}.{key}.holds_{end}": (band[i] if band else None)
                 for (g, key), band in bands.items() for i, end in enumerate(("from", "to"))}
        rule = (f"{curves.measure} in >= 90% of episodes" if curves.measure != "return"
                else "mean return within 10% of its best")
        table = Table(title=f"robustness on {targets[0].env.id}: {settings.episodes} episodes per point; "
                            f"holds over: the widest range of grid values with {rule}")
        table.add_column("policy")
        for a in axes:
            table.add_column(f"{a.key.replace('_', '-')}: return at " + ", ".join(f"{v:g}" for v in a.values),
                             justify="right")
            table.add_column("holds over", justify="right")
        for g in curves.groups:
            cells = []
            for a in axes:
                band = bands[(g, a.key)]
                cells += [" ".join(f"{r:.0f}" for r in curves.curve(g, a.key)["return_mean"]),
                          "never" if band is None else show(band[0]) if band[0] == band[1]
                          else f"{show(band[0])} – {show(band[1])}"]
            table.add_row(g, *cells)
        (console or Console()).print(table)
        faults = [line for p in curves.points for line in p.faults]
        summary = RobustnessSummary(
            policies=[t.label for t in targets], vary={a.key: list(a.values) for a in axes}, measure=curves.measure,
            episodes=settings.episodes, seed=settings.seed, numerical_faults=len(faults), **holds,
            curves={g: {a.key: curves.curve(g, a.key) for a in axes} for g in curves.groups})
        return self.finish(run_dir, settings, summary, faults)

    def describe(self, settings: RobustnessSettings, copies: int = 1) -> str:
        return f"robustness of {', '.join(settings.policies)} to {', '.join(v.split('=')[0] for v in settings.vary)}"

    def headline(self, s: RobustnessSummary) -> dict[str, Any]:
        """Per policy and disturbance, the band it holds over as text ("0.15 – 0.25", "never"), and
        its ends as numbers."""
        keys = s.keys()
        ends = {k: v for k, v in keys.items() if k.endswith((".holds_from", ".holds_to"))}
        bands = {}
        for key in ends:
            if key.endswith(".holds_from"):
                base = key[: -len(".holds_from")]
                low, high = ends[key], ends[f"{base}.holds_to"]
                bands[f"{base}.holds"] = ("never" if low is None else show(low) if low == high
                                          else f"{show(low)} – {show(high)}")
        return {**bands, **ends}

    def metric(self, key: str) -> Metric:
        if key.endswith((".holds", ".holds_from", ".holds_to")):
            policy, disturbance, end = key.rsplit(".", 2)
            what = VARIABLES.get(disturbance, disturbance)
            word = {"holds": "holds over", "holds_from": "holds from", "holds_to": "holds up to"}[end]
            return Metric(key, f"{policy}: {word} {what}", "text" if end == "holds" else "number")
        return super().metric(key)

    def numbers(self, settings: RobustnessSettings, h: dict[str, Any]) -> list[Number]:
        return [n for k in h if k.endswith(".holds") and (n := self.metric(k).number(h))]

    def default_findings(self, settings: RobustnessSettings, h: dict[str, Any]) -> list[str]:
        return [k for k in h if k.endswith(".holds")]

    def notes(self, settings: RobustnessSettings, h: dict[str, Any]) -> str:
        return (f"{settings.episodes} episodes per point; holds: >= 90% of episodes succeed (or do not fall) "
                "over a range of grid values (null: at none)")

    def report(self, s: RobustnessSummary, settings: RobustnessSettings, console: Console) -> None:
        console.print(f"written: {s.run_dir}/summary.json, curves.csv, plots/robustness.png")  # the table: in `run`
        warn_faults(s)


ROBUSTNESS = RobustnessKind()
