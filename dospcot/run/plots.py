"""PNG plots of a run's learning curves and of a sweep's cells (matplotlib, no display needed)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: runs write PNGs on machines without a display
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FuncFormatter, LogLocator

from dospcot.run.run_folder import atomic_write

PANELS = (
    ("greedy_return", "greedy return"),
    ("agreement", "optimal-action agreement"),
    ("pseudo_accuracy", "pseudo-reward accuracy"),
    ("coverage", "coverage of U"),
)

MEASURED_TICKS = 8
"""A log axis with at most this many distinct x values ticks each of them (a label curve's budgets);
with more, it ticks 1, 2 and 5 of each decade."""


def plot_learning_curves(records: list[dict], path: Path, names: Sequence[str], title: str = "") -> None:
    """Four panels against each agent's env steps: greedy return, agreement, pseudo-reward accuracy
    and coverage (the last two only where the run co-trains), one line per agent, labelled by its
    name in ``names`` (by the records' ``agent`` index; a twin's two agents share a view)."""
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), constrained_layout=True)
    for ax, (key, label) in zip(axes.flat, PANELS, strict=True):
        for k, name in enumerate(names):
            rows = [r for r in records if r["agent"] == k]
            steps = np.array([r["env_steps"] for r in rows])
            values = np.array([r[key] for r in rows], dtype=float)
            if np.isfinite(values).any():
                ax.plot(steps, values, marker="o", label=name)
        ax.set_title(label)
        ax.set_xlabel("env steps per agent")
        ax.grid(alpha=0.3)
        if ax.has_data():
            ax.legend(fontsize="small")
        else:
            ax.text(0.5, 0.5, "no co-training in this run", ha="center", va="center", transform=ax.transAxes)
    fig.suptitle(title)
    atomic_write(path, partial(fig.savefig, dpi=100, format="png"))
    plt.close(fig)


@dataclass(frozen=True)
class Band:
    """A line and its band: ``mean`` against ``x``, shaded from ``low`` to ``high`` (equal lengths)."""

    label: str
    x: np.ndarray
    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def labelled(self, label: str) -> Band:
        """The same band under another legend label."""
        return replace(self, label=label)


def plot_bands(
    panels: dict[str, list[Band]],
    xlabel: str,
    ylabel: str,
    path: Path,
    *,
    log_x: bool = False,
    markers: bool = False,
    share_y: bool = True,
    legend_below: bool = False,
) -> None:
    """One panel per key of ``panels`` (its title), each line with its shaded band; ``legend_below``:
    each panel's legend under it, one line per band (for labels too long to sit inside the axes).

    A band of one point (an arm measured at one budget) shows its interval as an error bar, which a
    shaded band of one point cannot; where every band of a panel sits at one x, the points stand a
    little apart around it, so their bars do not hide each other, and the axis ticks that x alone."""
    cols = 1 if legend_below else min(3, len(panels))
    rows = -(-len(panels) // cols)
    width, height = 5.2, 3.8
    if legend_below:  # one panel a row, wide enough for long labels, tall enough for a line each
        width, height = 7.5, height + 0.2 * max(len(bands) for bands in panels.values())
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(width * cols, height * rows),
        squeeze=False,
        constrained_layout=True,
        sharey=share_y,
    )
    for ax, (title, bands) in zip(axes.flat, panels.items(), strict=False):
        xs = np.unique(np.concatenate([np.asarray(band.x, dtype=float) for band in bands]))
        one_x = xs.size == 1
        for i, band in enumerate(bands):
            x = np.asarray(band.x, dtype=float)
            if one_x:  # side by side, 3% of the x apart
                x = x * (1 + 0.03 * (i - (len(bands) - 1) / 2))
            (line,) = ax.plot(x, band.mean, marker="o" if markers else None, ms=4, label=band.label)
            if x.size == 1:
                bar = np.array([band.mean - band.low, band.high - band.mean]).reshape(2, 1)
                ax.errorbar(x, band.mean, yerr=np.clip(bar, 0, None), color=line.get_color(), capsize=3)
            else:
                ax.fill_between(x, band.low, band.high, color=line.get_color(), alpha=0.2, linewidth=0)
        if one_x:
            ax.set_xlim(xs[0] * (0.97 - 0.03 * len(bands)), xs[0] * (1.03 + 0.03 * len(bands)))
        ax.set_title(title)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        if log_x:  # written out (budgets read as 20, not 2 x 10^1)
            ax.set_xscale("log")
            ax.minorticks_off()
            if xs.size <= MEASURED_TICKS:  # a curve read at a few budgets: tick each one measured
                ax.set_xticks(xs, [f"{x:.3g}" for x in xs])
            else:  # at 1, 2 and 5 of each decade
                ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
        if one_x:  # after the scale, which sets its own ticks
            ax.set_xticks(xs, [f"{xs[0]:g}"])
            ax.minorticks_off()
        ax.grid(alpha=0.3)
        if legend_below:
            ax.legend(fontsize="small", loc="upper center", bbox_to_anchor=(0.5, -0.18), ncols=1)
        else:
            ax.legend(fontsize="small")
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    atomic_write(path, partial(fig.savefig, dpi=100, format="png"))
    plt.close(fig)
