"""The benchmarks page's table of recorded results, generated from benchmarks/results/*.json at every
docs build, so no number on it is typed by hand.

MkDocs runs this file as a hook (mkdocs.yml: `hooks:`): in docs/benchmarks.md the line
`<!-- benchmark-results -->` becomes one row per result file (a benchmark of several envs writes one
file per env, e.g. mbrl-pendulum.json), naming the file, its date, commit and command line, and its
headline facts, each read from the file; a benchmark script with no file reads "not yet run", a file
without a date "undated", one without its command line "no command line recorded". A statistic over
seeds (across seeds, P(A > B), steps to a threshold and their ratio) is computed at the build from the
file's per-seed values, by docs/hooks/results.py (motorlab.intervals, motorlab.stats), never copied
from the text an older run stored beside them.

tests/test_benchmark_table.py checks every fact in the table against its JSON.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

PLACEHOLDER = "<!-- benchmark-results -->"
PAGE = "benchmarks.md"
ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
# modules in benchmarks/ that the benchmarks import: not benchmarks of their own
HELPERS = frozenset({"provenance", "mbrl_body", "user_reacher_reward", "bodies", "sac_tune", "protocol_time"})


def _results_hook():
    """docs/hooks/results.py (MkDocs loads hooks from their files, not as a package)."""
    if "results" in sys.modules and getattr(sys.modules["results"], "__file__", None) == str(Path(__file__).parent
                                                                                               / "results.py"):
        return sys.modules["results"]
    spec = importlib.util.spec_from_file_location("results", Path(__file__).parent / "results.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


results = _results_hook()


@dataclass(frozen=True)
class Fact:
    """One number of a result file, as the table shows it: its label, where it sits in the JSON (a
    path of keys), and how it is written."""

    label: str
    path: tuple[str, ...]
    # "count", "ms", "ratio", "percent", "number", "text", "met" (or a form of docs/hooks/results.py); over
    # seeds, computed at the build: "seeds" or "seeds:<form>" (per-seed values), "steps" (steps to a
    # threshold), "p_better" and "steps_ratio" (path against other)
    form: str
    other: tuple[str, ...] = ()  # the second side of "p_better" (B) and "steps_ratio" (the numerator)
    sides: tuple[str, str] = ("A", "B")  # what "p_better" calls path's side and other's

    @staticmethod
    def _at(data: dict[str, Any], path: tuple[str, ...]) -> Any:
        for key in path:
            data = data[key]
        return data

    def value(self, data: dict[str, Any]) -> Any:
        return self._at(data, self.path)

    def text(self, data: dict[str, Any]) -> str:
        return f"{self.label} {self.shown(data)}".strip()

    def shown(self, data: dict[str, Any]) -> str:
        value = self.value(data)
        if self.form.startswith("seeds"):
            return results.across_text(value, self.form.partition(":")[2] or "number")
        if self.form == "steps":
            return results.steps_of(value).text
        if self.form == "p_better":
            return results.p_better_text(value, self._at(data, self.other), *self.sides)
        if self.form == "steps_ratio":
            return results.ratio_text(value, self._at(data, self.other))
        return show(value, self.form)

    def present(self, data: dict[str, Any]) -> bool:
        """The file has this number (an older run's file may not)."""
        for path in (self.path, self.other):
            at = data
            for key in path:
                if not isinstance(at, dict) or key not in at:
                    return False
                at = at[key]
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
    if form in results.FORMS:
        return results.FORMS[form](value)
    return str(value)


def facts(benchmark: str, data: dict[str, Any]) -> list[Fact]:
    """The headline facts of a result file, by the benchmark that wrote it."""
    if benchmark == "mbrl":
        return [f for f in _mbrl() if f.present(data)]
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


def _mbrl() -> list[Fact]:
    return [Fact("loop:", ("loop", "steps_to_threshold"), "steps"),
            Fact("target", ("targets", "loop_seeds", "target"), "text"),
            Fact("target met:", ("targets", "loop_seeds", "met"), "met"),
            Fact("SAC (SB3's defaults):", ("sac", "steps_to_threshold"), "steps"),
            Fact("SAC / loop", ("loop", "steps_to_threshold"), "steps_ratio", other=("sac", "steps_to_threshold")),
            Fact("tuned SAC (benchmarks/sac_tune.py):", ("sac_tuned", "steps_to_threshold"), "steps"),
            Fact("tuned SAC / loop", ("loop", "steps_to_threshold"), "steps_ratio",
                 other=("sac_tuned", "steps_to_threshold")),
            Fact("plan per control step:", ("targets", "plan_ms", "median"), "ms")]


def _sar_study(data: dict[str, Any]) -> list[Fact]:
    learning = data.get("learning") or {}
    where = f"{learning.get('env')} at {learning.get('env_steps_per_seed', 0):,} env steps"
    return [Fact(f"success on {where}, reference SAC:", ("learning", "reference_sac", "success_per_seed"),
                 "seeds:percent"),
            Fact("sar-sac-fast:", ("learning", "sar_sac_fast", "success_per_seed"), "seeds:percent"),
            Fact("sar-sac-fast's env steps/s over the reference's:", ("speedup_over_reference", "sar_sac_fast"),
                 "ratio")]


# benchmark -> the numbers its row shows before its targets (each a path into its JSON)
NAMED = {
    "sar_study": _sar_study,
    "sar_robot": lambda d: [Fact("return, SAR-RL:", ("sar_rl", "per_seed"), "seeds"),
                            Fact("RL-E2E:", ("rl_e2e", "per_seed"), "seeds"),
                            Fact("", ("sar_rl", "per_seed"), "p_better", other=("rl_e2e", "per_seed"),
                                 sides=("SAR-RL", "RL-E2E")),
                            Fact("wall:", ("wall_seconds",), "min_of_s")],
    "sar_legs": lambda d: [Fact("full study projected, hours on this machine:", ("study", "projected_full_hours"),
                                "number"),
                           Fact("on a Ray cluster, a machine per seed:",
                                ("study", "projected_full_hours_ray_cluster_one_machine_per_seed"), "number"),
                           Fact(f"at 1/{d.get('study', {}).get('scale')} of the budgets, return SAR-RL:",
                                ("study", "arms", "sar-rl", "return", "per_seed"), "seeds"),
                           Fact("RL-E2E:", ("study", "arms", "rl-e2e", "return", "per_seed"), "seeds"),
                           Fact("", ("study", "arms", "sar-rl", "return", "per_seed"), "p_better",
                                other=("study", "arms", "rl-e2e", "return", "per_seed"), sides=("SAR-RL", "RL-E2E"))],
    "mbrl_bodies": lambda d: [f for m, label in BODY_METHODS.items() for f in (
        Fact(f"{label}: median share of the random-to-oracle gap", ("targets", m, "median"), "percent"),
        Fact(f"bodies at its target, of {(d.get('targets') or {}).get(m, {}).get('of')}:", ("targets", m, "k"),
             "count"))],
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
        Fact("plain, motorlab / SB3 steps:", ("plain", "sb3_ppo_defaults"), "steps_ratio",
             other=("plain", "motorlab_fast")),
        Fact("delayed:", ("delayed_tau_0.2s_action_and_observation", "sb3_ppo_defaults"), "steps_ratio",
             other=("delayed_tau_0.2s_action_and_observation", "motorlab_fast"))],
    "sar_study_overlap": lambda d: [Fact("two chains at once over one after another:", ("speedup",), "ratio"),
                                    Fact("same numbers both ways:", ("same_numbers",), "met")],
    "tune": lambda d: [Fact("tuned / defaults steps:", ("sb3_ppo_defaults_history10", "censored"), "steps_ratio",
                            other=("motorlab_tuned", "censored")),
                       Fact("tuned:", ("motorlab_tuned", "censored"), "steps"),
                       Fact("defaults:", ("sb3_ppo_defaults_history10", "censored"), "steps"),
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


UNDATED = "**undated**"
NO_COMMAND = "**no command line recorded**"


def dated(path: Path, data: dict[str, Any]) -> str:
    """The run's date, from the file; a file without one is shown undated, with the day its last
    version was committed (when the run happened is not known: only when it was kept)."""
    if isinstance(data.get("date"), str):
        return data["date"][:10]
    try:
        day = subprocess.run(["git", "log", "-1", "--format=%cs", "--", str(path)], cwd=ROOT, capture_output=True,
                             text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        day = ""
    return f"{UNDATED} (file committed {day})" if day else UNDATED


def command(script: str, data: dict[str, Any]) -> str:
    """The command line the run recorded (provenance.Recorder's argv), or that it recorded none."""
    argv = data.get("argv")
    if not isinstance(argv, list):
        return NO_COMMAND
    line = " ".join([f"benchmarks/{script}.py", *map(str, argv)]).replace("`", "'").replace("|", "\\|")
    return f"`{line}`"


# benchmarks whose numbers are claims about learning: their settings are chosen on development seeds,
# and a result is a headline only when provenance.Harness recorded it on held-out seeds
SCIENCE = frozenset({"mbrl", "mbrl_bodies"})


def provenance_note(script: str, data: dict[str, Any]) -> str:
    """For a science benchmark: "**in-sample**" when its file is no headline (recorded on the seeds
    its settings were chosen on), else the held-out seeds and the development log's count."""
    if script not in SCIENCE:
        return ""
    prov = data.get("provenance") or {}
    if prov.get("mode") != "headline":
        return ("**in-sample** (recorded on development seeds, the ones its settings were chosen on; "
                "not a headline): ")
    dev = prov.get("development") or {}
    seeds = prov.get("seeds") or []
    return (f"headline on held-out seeds {seeds[0]}–{seeds[-1]}, after {dev.get('configurations_tried', 0)} "
            f"configuration(s) in `{dev.get('log')}`; {in_sample(dev)}: ")


def in_sample(dev: dict[str, Any]) -> str:
    """The development runs' numbers beside a headline: those of its own settings where the log has them,
    else the log's last run (other settings), so a reader sees how much held-out and in-sample differ."""
    runs = dev.get("in_sample") or []
    if runs:
        return f"in-sample with these settings ({len(runs)} run(s), seeds {runs[-1]['seeds']}): " \
               f"{_loop_text(runs[-1]['result'])}"
    log = ROOT / str(dev.get("log", ""))
    lines = [json.loads(x) for x in log.read_text().splitlines() if x.strip()] if log.is_file() else []
    if not lines:
        return "no development run"
    last = lines[-1]
    return f"no development run of these settings; the log's last (seeds {last['seeds']}, other settings): " \
           f"{_loop_text(last['result'])}"


def _loop_text(result: dict[str, Any]) -> str:
    steps = ((result.get("loop") or {}).get("steps_to_threshold") or {})
    if steps.get("text"):
        return f"loop {steps['text']}"
    shares = _shares_text(result)  # mbrl_bodies: the share of the gap each method closed
    return shares or "(no loop result)"


BODY_METHODS = {"loop": "loop", "mpc_user": "one-shot, user's reward", "mpc_learned": "one-shot, learned reward"}


def _shares_text(result: dict[str, Any]) -> str:
    targets = result.get("targets") or {}
    parts = [f"{label} median {show(targets[m]['median'], 'percent')} of the gap ({targets[m]['k']} of "
             f"{targets[m]['of']} at its target)" for m, label in BODY_METHODS.items()
             if isinstance(targets.get(m), dict) and "median" in targets[m]]
    return "; ".join(parts)


def rows(results: Path = BENCHMARKS / "results") -> list[tuple[str, str, str, str, str]]:
    """(script, file, date and commit, command line, facts) per result file; a script without one:
    "not yet run"."""
    out = []
    for script in scripts():
        files = result_files(script, results)
        if not files:
            out.append((f"`{script}.py`", "–", "–", "–", "not yet run"))
        for path in files:
            data = json.loads(path.read_text())
            commit = (data.get("git") or {}).get("commit") or ""
            when = dated(path, data) + (f", `{commit[:7]}`" if commit else "")
            if (data.get("git") or {}).get("changed_during_run"):
                when += " (the tree changed during the run)"  # see the file's git.at_end
            shown = "; ".join(f.text(data) for f in facts(data.get("benchmark", script), data))
            if data.get("quick"):
                shown = f"(a `--quick` smoke run) {shown}"
            shown = f"{provenance_note(script, data)}{shown}"
            out.append((f"`{script}.py`", f"`{path.name}`", when, command(script, data),
                        shown or "(no headline facts named for it yet)"))
    return out


def render(results: Path = BENCHMARKS / "results") -> str:
    lines = ["| benchmark | result file | run on | command line | recorded |", "|---|---|---|---|---|"]
    lines += [f"| {' | '.join(row)} |" for row in rows(results)]
    return "\n".join(lines) + "\n"


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs hook
    if page.file.src_uri != PAGE:
        return markdown
    if PLACEHOLDER not in markdown:
        raise RuntimeError(f"docs/{PAGE} lost its {PLACEHOLDER} line")
    return markdown.replace(PLACEHOLDER, render())
