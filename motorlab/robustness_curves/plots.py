"""The robustness figure: return, and the rate that holds (success or no fall), against each
disturbance, one line per policy with a band over its episodes and seeds."""

from __future__ import annotations

from pathlib import Path

from motorlab.report.plots import STYLE, plt, save_figure
from motorlab.robustness_curves.curves import Curves


def robustness_plot(curves: Curves, path: Path, title: str) -> Path | None:
    """One column per varied disturbance; top row the return (line: mean, band: quartiles over all
    episodes of all seeds), bottom row the success or no-fall rate (band: lowest to highest seed)."""
    rows = 1 if curves.measure == "return" else 2
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(rows, len(curves.axes), figsize=(4.2 * len(curves.axes), 3.2 * rows),
                                 squeeze=False, sharex="col")
        for col, axis in enumerate(curves.axes):
            for k, group in enumerate(curves.groups):
                c = curves.curve(group, axis.key)
                colour = f"C{k}"
                top = axes[0][col]
                top.plot(c["values"], c["return_mean"], "o-", color=colour, label=group, ms=3)
                top.fill_between(c["values"], c["return_q25"], c["return_q75"], color=colour, alpha=0.15, lw=0)
                if rows == 2:
                    pts = curves.at(group, axis.key)
                    rate = [curves.rate(p) for p in pts]
                    low = [min(curves.rate([q]) for q in p) for p in pts]
                    high = [max(curves.rate([q]) for q in p) for p in pts]
                    bottom = axes[1][col]
                    bottom.plot(c["values"], rate, "o-", color=colour, label=group, ms=3)
                    if len(pts[0]) > 1:
                        bottom.fill_between(c["values"], low, high, color=colour, alpha=0.15, lw=0)
            axes[0][col].set_title(axis.label, fontsize=9)
            axes[0][col].set_ylabel("return" if col == 0 else "")
            if rows == 2:
                axes[1][col].set_ylim(-0.03, 1.03)
                axes[1][col].set_ylabel(f"{curves.measure} rate" if col == 0 else "")
            axes[-1][col].set_xlabel(axis.label)
        axes[0][0].legend(fontsize=7)
        fig.suptitle(title, fontsize=10)
        caption = (f"Return (mean; band: quartiles over {curves.episodes} episodes per seed) and "
                   + ("" if rows == 1 else f"{curves.measure} rate (band: lowest to highest seed) ")
                   + "of each policy as the disturbance grows, the other disturbances at the policy's own settings.")
        return save_figure(fig, path, caption)
