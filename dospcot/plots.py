"""PNG plots of a run's learning curves (matplotlib, no display needed)."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: runs write PNGs on machines without a display
import matplotlib.pyplot as plt
import numpy as np

from dospcot.run_folder import atomic_write

PANELS = (
    ("greedy_return", "greedy return"),
    ("agreement", "optimal-action agreement"),
    ("pseudo_accuracy", "pseudo-reward accuracy"),
    ("coverage", "coverage of U"),
)


def plot_learning_curves(records: list[dict], path: Path, title: str = "") -> None:
    """Four panels against each agent's env steps: greedy return, agreement, pseudo-reward accuracy
    and coverage (the last two only where the run co-trains), one line per view."""
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), constrained_layout=True)
    for ax, (key, label) in zip(axes.flat, PANELS, strict=True):
        for view in dict.fromkeys(r["view"] for r in records):
            rows = [r for r in records if r["view"] == view]
            steps = np.array([r["env_steps"] for r in rows])
            values = np.array([r[key] for r in rows], dtype=float)
            if np.isfinite(values).any():
                ax.plot(steps, values, marker="o", label=view)
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
