"""The benchmarks page's table of recorded results, generated from benchmarks/results/*.json at every
docs build, so no number on it is typed by hand.

MkDocs runs this file as a hook (mkdocs.yml: `hooks:`): in docs/benchmarks.md the line
`<!-- benchmark-results -->` becomes one row per result file (a benchmark of several envs writes one
file per env, e.g. mbrl-pendulum.json), naming the file, its date and commit, and its headline
facts, each read from the file; a benchmark script with no file reads "not yet run".

tests/test_benchmark_table.py checks every fact in the table against its JSON.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PLACEHOLDER = "<!-- benchmark-results -->"
PAGE = "benchmarks.md"
ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
# modules in benchmarks/ that the benchmarks import: not benchmarks of their own
HELPERS = frozenset({"provenance", "mbrl_body", "user_reacher_reward"})


@dataclass(frozen=True)
class Fact:
    """One number of a result file, as the table shows it: its label, where it sits in the JSON (a
    path of keys), and how it is written."""

    label: str
    path: tuple[str, ...]
    form: str  # "count", "ms", "ratio", "percent", "number", "text", "met"

    def value(self, data: dict[str, Any]) -> Any:
        for key in self.path:
            data = data[key]
        return data

    def text(self, data: dict[str, Any]) -> str:
        return f"{self.label} {show(self.value(data), self.form)}"

    def present(self, data: dict[str, Any]) -> bool:
        """The file has this number (an older run's file may not)."""
        for key in self.path:
            if not isinstance(data, dict) or key not in data:
                return False
            data = data[key]
        return True


def show(value: Any, form: str) -> str:
    if value is None:
        return "–"
    if form == "met":
        return "yes" if value else "**no**"
    if form == "ms":
        return f"{value:.1f} ms"
    if form == "ratio":
        return f"{value:.3g}x"
    if form == "count":
        return f"{value:,}"
    if form == "percent":
        return f"{100 * value:.0f}%"
    if form == "number":
        return f"{value:,.3g}" if abs(value) < 1000 else f"{value:,.0f}"
    return str(value)


def facts(benchmark: str, data: dict[str, Any]) -> list[Fact]:
    """The headline facts of a result file, by the benchmark that wrote it."""
    if benchmark == "mbrl":
        return [Fact("loop:", ("loop", "steps_to_threshold", "text"), "text"),
                Fact("target", ("targets", "loop_seeds", "target"), "text"),
                Fact("target met:", ("targets", "loop_seeds", "met"), "met"),
                Fact("SAC:", ("sac", "steps_to_threshold", "text"), "text"),
                Fact("SAC / loop", ("ratio_sac_over_loop", "text"), "text"),
                Fact("plan per control step:", ("targets", "plan_ms", "median"), "ms")]
    if benchmark == "plan_latency":
        return [*(Fact(f"{env}:", ("envs", env, "ms_median"), "ms") for env in data["envs"]),
                Fact("every env under 50 ms:", ("all_met",), "met")]
    if benchmark == "mpc_reward":
        return [Fact(f"{group}: learned reward / exact", ("groups", group, "ratios", "learned_over_builtin"), "ratio")
                for group in data["groups"]] + \
               [Fact(f"{group}: user's reward / bundled", ("groups", group, "ratios", "user_over_builtin"), "ratio")
                for group in data["groups"]]
    named = NAMED.get(benchmark)
    # the named facts a file has (an older run's file may lack a newer key), then its targets
    return [f for f in (named(data) if named else []) if f.present(data)] + target_facts(data)


def _sar_study(data: dict[str, Any]) -> list[Fact]:
    learning = data.get("learning") or {}
    where = f"{learning.get('env')} at {learning.get('env_steps_per_seed', 0):,} env steps"
    return [Fact(f"success on {where}, reference SAC:", ("learning", "reference_sac", "success", "value"), "percent"),
            Fact("sar-sac-fast:", ("learning", "sar_sac_fast", "success", "value"), "percent"),
            Fact("sar-sac-fast's env steps/s over the reference's:", ("speedup_over_reference", "sar_sac_fast"),
                 "ratio")]


# benchmark -> the numbers its row shows before its targets (each a path into its JSON)
NAMED = {
    "sar_study": _sar_study,
    "sar_robot": lambda d: [Fact("return, SAR-RL:", ("sar_rl", "value"), "number"),
                            Fact("RL-E2E:", ("rl_e2e", "value"), "number"),
                            Fact("P(SAR-RL > RL-E2E):", ("p_sar_better", "p"), "number"),
                            Fact("wall:", ("wall_seconds",), "number")],
    "sar_legs": lambda d: [Fact("full study projected, hours on this machine:", ("study", "projected_full_hours"),
                                "number"),
                           Fact("on a Ray cluster, a machine per seed:",
                                ("study", "projected_full_hours_ray_cluster_one_machine_per_seed"), "number"),
                           Fact(f"at 1/{d.get('study', {}).get('scale')} of the budgets, return SAR-RL:",
                                ("study", "arms", "sar-rl", "return", "value"), "number"),
                           Fact("RL-E2E:", ("study", "arms", "rl-e2e", "return", "value"), "number")],
    "dynamics_fit": lambda d: [Fact("fit speedup over the reference:", ("speedup",), "ratio"),
                               Fact("validation MSE / the reference's:", ("mse_ratio",), "ratio")],
    "dynamics_collect": lambda d: [Fact("transitions/s over the reference's:", ("ratio",), "ratio")],
    "evaluate_parallel": lambda d: [Fact("every core over one process:", ("ratio",), "ratio")],
    "sar_decode": lambda d: [Fact("scikit-learn's time / motorlab's:", ("ratio_sklearn_over_motorlab",), "ratio")],
    "upkie_fps": lambda d: [Fact("env steps/s over Upkie's defaults:", ("speedup_k2_over_upkie_defaults",), "ratio")],
    "mpc": lambda d: [Fact("plan per control step:", ("motorlab", "plan_ms_median"), "ms"),
                      Fact("return:", ("motorlab", "return_mean"), "number"),
                      Fact("plan speedup over EvoTorch CEM:", ("plan_speedup",), "ratio")],
    "pendulum_steps_to_success": lambda d: [
        Fact("plain, motorlab / SB3 steps:", ("plain", "steps_ratio_motorlab_over_sb3", "text"), "text"),
        Fact("delayed:", ("delayed_tau_0.2s_action_and_observation", "steps_ratio_motorlab_over_sb3", "text"), "text")],
    "sar_study_overlap": lambda d: [Fact("two chains at once over one after another:", ("speedup",), "ratio"),
                                    Fact("same numbers both ways:", ("same_numbers",), "met")],
    "tune": lambda d: [Fact("tuned / defaults steps:", ("ratio_tuned_over_defaults", "text"), "text"),
                       Fact("tuned median:", ("motorlab_tuned", "median_text"), "text"),
                       Fact("defaults:", ("sb3_ppo_defaults_history10", "median_text"), "text"),
                       Fact("wall minutes:", ("wall_minutes",), "number"),
                       Fact("ratio met:", ("targets", "ratio_met"), "met"),
                       Fact("minutes met:", ("targets", "minutes_met"), "met")],
}


def target_facts(data: dict[str, Any]) -> list[Fact]:
    """Any other benchmark: whether each of its targets is met, wherever its file says so."""
    if isinstance(data.get("met"), dict):
        return [Fact(f"{k} met:", ("met", k), "met") for k in data["met"]]
    if isinstance(data.get("targets"), dict) and all(isinstance(v, dict) and "met" in v for v in data["targets"].values()):
        return [Fact(f"{k} met:", ("targets", k, "met"), "met") for k in data["targets"]]
    for key in ("meets_target", "meets_scaled_targets", "meets_targets", "all_met", "met"):
        if isinstance(data.get(key), bool):
            return [Fact("target met:", (key,), "met")]
    # several named ones: meets_ratio_target, meets_rate_target, ...
    return [Fact(f"{k.removeprefix('meets_').replace('_', ' ')} met:", (k,), "met")
            for k, v in data.items() if k.startswith("meets_") and isinstance(v, bool)]


def scripts() -> list[str]:
    return sorted(p.stem for p in BENCHMARKS.glob("*.py") if p.stem not in HELPERS)


def result_files(script: str, results: Path) -> list[Path]:
    """benchmarks/results/<script>.json, or <script>-<env>.json for a benchmark of several envs."""
    return sorted(p for p in results.glob("*.json") if p.stem == script or p.stem.startswith(f"{script}-"))


def dated(path: Path, data: dict[str, Any]) -> str:
    """The run's date: the file's own, else the day its last version was committed."""
    if isinstance(data.get("date"), str):
        return data["date"][:10]
    try:
        day = subprocess.run(["git", "log", "-1", "--format=%cs", "--", str(path)], cwd=ROOT, capture_output=True,
                             text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        day = ""
    return day or "undated"


def rows(results: Path = BENCHMARKS / "results") -> list[tuple[str, str, str, str]]:
    """(script, file, date and commit, facts) per result file; a script without one: "not yet run"."""
    out = []
    for script in scripts():
        files = result_files(script, results)
        if not files:
            out.append((f"`{script}.py`", "–", "–", "not yet run"))
        for path in files:
            data = json.loads(path.read_text())
            commit = (data.get("git") or {}).get("commit") or ""
            when = dated(path, data) + (f", `{commit[:7]}`" if commit else "")
            if (data.get("git") or {}).get("changed_during_run"):
                when += " (the tree changed during the run)"  # see the file's git.at_end
            shown = "; ".join(f.text(data) for f in facts(data.get("benchmark", script), data))
            if data.get("quick"):
                shown = f"(a `--quick` smoke run) {shown}"
            out.append((f"`{script}.py`", f"`{path.name}`", when, shown or "(no headline facts named for it yet)"))
    return out


def render(results: Path = BENCHMARKS / "results") -> str:
    lines = ["| benchmark | result file | run on | recorded |", "|---|---|---|---|"]
    lines += [f"| {' | '.join(row)} |" for row in rows(results)]
    return "\n".join(lines) + "\n"


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs hook
    if page.file.src_uri != PAGE:
        return markdown
    if PLACEHOLDER not in markdown:
        raise RuntimeError(f"docs/{PAGE} lost its {PLACEHOLDER} line")
    return markdown.replace(PLACEHOLDER, render())
