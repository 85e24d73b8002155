"""The `ablate` step kind: what each synergy of a SAR policy does, measured as the return and
success its policy loses when that synergy's command is zeroed (motorlab.synergy_runs.ablation)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import Field
from rich.console import Console
from rich.table import Table

from motorlab.kinds.evaluate import EnvWorkers
from motorlab.report.results import Metric, Number, fixed
from motorlab.settings import MAX_SEED, Settings, Summary
from motorlab.stepkind import Ref, StepKind, warn_faults

if TYPE_CHECKING:
    from motorlab.synergy_runs.ablation import MeanInterval

FIGURE = "ablation.png"


class AblateSettings(Settings):
    run: str = Field(description="A training run folder whose policy acts through a SAR (trained with --sar)")
    episodes: int = Field(50, gt=0, description="Episodes per condition (intact, and each synergy zeroed), from the "
                          "same reset seeds in each; at least 5 for an interval")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="Random seed (env resets: episode i starts from seed + i)")
    workers: EnvWorkers = None


class AblateSummary(Summary):
    """Per synergy k (1-based, coordinate k - 1 of the policy's action), in the lists' order: the
    ablated return and success, and what was lost (intact - ablated, the mean of the paired
    per-episode differences) with its 95% interval (`interval`). None where it cannot be measured
    (success on an env that defines none; fewer than 5 episodes without numerical faults)."""

    env_id: str
    sar: str
    sar_method: str
    phi: float
    n_synergies: int
    episodes: int
    seed: int
    interval: str  # how every "_low"/"_high" pair of the lost numbers was computed
    baseline_return_mean: float | None
    baseline_return_mean_ci_low: float | None
    baseline_return_mean_ci_high: float | None
    baseline_success_rate: float | None
    baseline_success_rate_ci_low: float | None  # Wilson score interval
    baseline_success_rate_ci_high: float | None
    synergy: list[int]
    return_mean: list[float | None]
    success_rate: list[float | None]
    return_lost: list[float | None]
    return_lost_low: list[float | None]
    return_lost_high: list[float | None]
    success_lost: list[float | None]
    success_lost_low: list[float | None]
    success_lost_high: list[float | None]
    top_synergy: int | None  # the synergy whose loss costs the most return
    top_return_lost: float | None
    top_return_lost_ci_low: float | None
    top_return_lost_ci_high: float | None
    numerical_faults: int


class AblateKind(StepKind[AblateSettings, AblateSummary]):
    """Zero each synergy's command of a SAR policy in turn; report the return and success lost.

    The run's deterministic policy acts on the same episodes (the same reset seeds) intact and with
    each synergy coordinate of its action set to 0 before the SAR decodes it. Zero is the middle of
    the range the synergy took in the data the SAR was fitted on (every SAR method scales it to
    [-1, 1]), not "no activation". What is lost is intact - ablated, the mean of the per-episode
    differences, with a 95% percentile-bootstrap interval over episodes (scipy.stats.bootstrap);
    the intact success rate has a Wilson interval. Writes ablation.png and summary.json.
    """

    name = "ablate"
    command = "synergies ablate"
    what = "ablate each synergy of {run} ({episodes} episodes)"
    key_figures = (FIGURE,)
    headline_keys = ("n_synergies", "episodes", "baseline_return_mean", "baseline_return_mean_ci_low",
                     "baseline_return_mean_ci_high", "baseline_success_rate", "baseline_success_rate_ci_low",
                     "baseline_success_rate_ci_high", "top_synergy", "top_return_lost", "top_return_lost_ci_low",
                     "top_return_lost_ci_high")
    metrics = (Metric("baseline_return_mean", "intact return (95% CI over episodes)", "return"),
               Metric("baseline_success_rate", "intact success (95% Wilson CI)", "percent"),
               Metric("top_return_lost", "most return lost by zeroing one synergy", "return"),
               Metric("n_synergies", "synergies", "count"),
               Metric("episodes", "episodes per condition", "count", setup=True))
    findings = ("top_return_lost",)
    refs = (Ref("run", ("policy",)),)
    arguments = ("run",)
    examples = ("motorlab synergies ablate runs/sar-rl --episodes 50",
                "motorlab synergies ablate runs/sar-rl --episodes 200 --seed 1000 --workers 2")

    def run(self, settings: AblateSettings, out: Path | None = None, console: Console | None = None,
            progress: bool = True) -> AblateSummary:
        from motorlab.synergy_runs.ablation import INTERVAL_METHOD, ablate, ablation_plot

        s = settings
        a = ablate(Path(s.run), s.episodes, s.seed, s.workers, progress,
                   before_work=lambda: self.refuse_finished_out(out))
        run_dir = self.start(out)
        ablation_plot(a, run_dir / FIGURE)
        base, top = a.baseline_return, a.top()

        def column(get) -> list[float | None]:
            return [get(loss) for loss in a.losses]

        summary = AblateSummary(
            env_id=a.env_id, sar=a.sar, sar_method=a.sar_method, phi=a.phi, n_synergies=a.n_synergies,
            episodes=a.episodes, seed=a.seed, interval=INTERVAL_METHOD,
            baseline_return_mean=base.mean if base else None, baseline_return_mean_ci_low=base.low if base else None,
            baseline_return_mean_ci_high=base.high if base else None,
            baseline_success_rate=a.baseline.success_rate,
            baseline_success_rate_ci_low=a.baseline_success[0] if a.baseline_success else None,
            baseline_success_rate_ci_high=a.baseline_success[1] if a.baseline_success else None,
            synergy=[loss.synergy for loss in a.losses],
            return_mean=column(lambda x: x.return_mean), success_rate=column(lambda x: x.success_rate),
            return_lost=column(lambda x: _part(x.return_lost, "mean")),
            return_lost_low=column(lambda x: _part(x.return_lost, "low")),
            return_lost_high=column(lambda x: _part(x.return_lost, "high")),
            success_lost=column(lambda x: _part(x.success_lost, "mean")),
            success_lost_low=column(lambda x: _part(x.success_lost, "low")),
            success_lost_high=column(lambda x: _part(x.success_lost, "high")),
            top_synergy=top.synergy if top else None,
            top_return_lost=top.return_lost.mean if top and top.return_lost else None,
            top_return_lost_ci_low=top.return_lost.low if top and top.return_lost else None,
            top_return_lost_ci_high=top.return_lost.high if top and top.return_lost else None,
            numerical_faults=len(a.fault_log))
        return self.finish(run_dir, settings, summary, a.fault_log)

    def numbers(self, settings: AblateSettings, h: dict[str, Any]) -> list[Number]:
        top = h.get("top_synergy")
        return [Number(n.key, f"return lost without synergy {top} (95% CI over episodes)", n.value, n.text, n.setup)
                if n.key == "top_return_lost" and top is not None else n for n in super().numbers(settings, h)]

    def report(self, s: AblateSummary, settings: AblateSettings, console: Console) -> None:
        def interval(mean: float | None, low: float | None, high: float | None, spec: str) -> str:
            if mean is None:
                return "–"
            return f"{fixed(mean, spec)} [{fixed(low, spec)}, {fixed(high, spec)}]"

        table = Table(title=f"{s.n_synergies} synergies ({s.sar_method}, phi {s.phi:g}) of {settings.run} zeroed one "
                      f"at a time: {s.env_id}, {s.episodes} episodes each from seed {s.seed}")
        for col in ("synergy zeroed", "return", "return lost [95% CI]", "success", "success lost [95% CI]"):
            table.add_column(col, justify="right")
        table.add_row("none (intact)", interval(s.baseline_return_mean, s.baseline_return_mean_ci_low,
                                                s.baseline_return_mean_ci_high, ".4g"),
                      "", interval(s.baseline_success_rate, s.baseline_success_rate_ci_low,
                                   s.baseline_success_rate_ci_high, ".0%"), "")
        for i, k in enumerate(s.synergy):
            table.add_row(str(k), fixed(s.return_mean[i], ".4g"),
                          interval(s.return_lost[i], s.return_lost_low[i], s.return_lost_high[i], ".3g"),
                          fixed(s.success_rate[i], ".0%"),
                          interval(s.success_lost[i], s.success_lost_low[i], s.success_lost_high[i], "+.0%"))
        console.print(table)
        console.print(f"lost = intact - ablated on the same episodes; intervals: {s.interval}; intact success: "
                      f"95% Wilson interval; zero = the middle of each synergy's fitted range, not no activation.",
                      soft_wrap=True)
        console.print(f"written: {s.run_dir}/summary.json, {s.run_dir}/{FIGURE}")
        warn_faults(s)


def _part(m: MeanInterval | None, part: str) -> float | None:
    """A mean or an end of its interval, None where nothing was measured."""
    return None if m is None else getattr(m, part)


ABLATE = AblateKind()
