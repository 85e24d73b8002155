"""Figures of a sweep: IQM with confidence intervals, probability of improvement, performance
profiles. Drawn here rather than with rliable.plot_utils so they share motorlab's style."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.ticker import PercentFormatter

from motorlab.report.plots import STYLE, plt, save_figure, steps_axis

LABELS = {"final_return": "final return", "success_rate": "success rate", "steps_to_success": "steps to success"}


def _label(metric: str) -> str:
    step, dot, base = metric.rpartition(".")
    return f"{step}: {LABELS.get(base, base)}" if dot else LABELS.get(base, base)


def interval_estimates(metrics: dict[str, dict[str, Any]], path: Path, title: str) -> Path | None:
    """One panel per metric: each setting's IQM (dot), 95% CI (bar) and single seeds (ticks)."""
    names = list(metrics)
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 0.6 * max(len(m) for m in metrics.values()) + 1.8),
                                 squeeze=False)
        for ax, metric in zip(axes[0], names):
            settings = list(metrics[metric])
            for y, s in enumerate(settings):
                e = metrics[metric][s]
                color = f"C{y % 10}"
                if e.get("ci"):  # a confidence interval only from 5 seeds (motorlab.intervals)
                    ax.plot(e["ci"], [y, y], lw=8, alpha=0.35, color=color, solid_capstyle="butt")
                ax.plot(e["values"], [y] * len(e["values"]), "|", ms=12, color=color, alpha=0.8)
                centre = e.get("value", e.get("median"))  # steps to success: the Kaplan-Meier median
                if centre is not None:
                    ax.plot(centre, y, "o", color=color, ms=6)
            ax.set_yticks(range(len(settings)), settings, fontsize=8)
            ax.set_ylim(-0.6, len(settings) - 0.4)
            ax.invert_yaxis()
            ax.set_xlabel(_label(metric))
            if metric.endswith("steps_to_success"):
                steps_axis(ax.xaxis)
            elif metric.endswith("success_rate"):
                ax.set_xlim(-0.02, 1.02)
                ax.xaxis.set_major_formatter(PercentFormatter(1.0))
        fig.suptitle(f"{title}: IQM or mean (dot), 95% bootstrap CI (bar); ticks are single seeds", fontsize=10)
        return save_figure(fig, path, "Each setting over its seeds (dot): the interquartile mean from 4 seeds, "
                                      "else the mean; steps to success: the Kaplan-Meier median, unsolved seeds "
                                      "censored at their budgets. Bar: the 95% bootstrap confidence interval, "
                                      "drawn only from 5 seeds. Ticks are single seeds.")


def improvement(pairs: dict[str, list[dict[str, Any]]], path: Path, title: str) -> Path | None:
    """P(setting A better than setting B) per metric, with its 95% CI; 0.5 is a coin flip."""
    rows = [(f"{_label(m)}: {p['a']} vs {p['b']}", p) for m, ps in pairs.items() for p in ps]
    with plt.rc_context(STYLE):
        fig, ax = plt.subplots(figsize=(7, 0.45 * len(rows) + 1.6))
        for y, (_, p) in enumerate(rows):
            if p.get("ci"):  # from 5 seeds a side
                ax.plot(p["ci"], [y, y], lw=8, alpha=0.35, color="C0", solid_capstyle="butt")
            ax.plot(p["p"], y, "o", color="C0")
        ax.axvline(0.5, color="gray", ls="--", lw=1)
        ax.set_yticks(range(len(rows)), [r for r, _ in rows], fontsize=8)
        ax.invert_yaxis()
        ax.set_xlim(-0.02, 1.02)
        ax.set_xlabel("probability that A is better than B (fewer steps for steps to success)")
        ax.set_title(f"{title}: probability of improvement", fontsize=10)
        return save_figure(fig, path, "Probability that setting A beats setting B on a random pair of seeds, with "
                                      "its 95% confidence interval where both have 5 seeds or more; 0.5 is a coin "
                                      "flip.")


def performance_profiles(profiles: dict[str, dict[str, Any]], path: Path, title: str) -> Path | None:
    """Fraction of runs scoring above tau, per setting, with the bootstrap band."""
    names = list(profiles)
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, len(names), figsize=(4.6 * len(names), 3.6), squeeze=False)
        for ax, metric in zip(axes[0], names):
            tau = np.array(profiles[metric]["tau"])
            for k, (s, p) in enumerate((s, p) for s, p in profiles[metric].items() if s != "tau"):
                ax.plot(tau, p["fraction"], color=f"C{k % 10}", label=s)
                ax.fill_between(tau, p["low"], p["high"], color=f"C{k % 10}", alpha=0.15, lw=0)
            ax.set_xlabel(f"{_label(metric)} τ")
            ax.set_ylabel("fraction of runs > τ")
            ax.set_ylim(-0.02, 1.02)
            ax.legend(fontsize=8)
        fig.suptitle(f"{title}: performance profiles", fontsize=10)
        return save_figure(fig, path, "Fraction of each setting's runs scoring above a threshold τ, against τ, "
                                      "with bootstrap bands.")


