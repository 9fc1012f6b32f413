"""The sweep and study figures' bands (dospcot.run.plots.plot_bands): what a reader sees of an arm
measured at one budget, and of a panel whose arms all sit at one x."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from dospcot.run import plots
from dospcot.run.plots import Band, plot_bands


@pytest.fixture
def drawn(monkeypatch):
    """The figures plot_bands draws, kept open rather than written."""
    figures = []
    monkeypatch.setattr(plots, "atomic_write", lambda path, write: figures.append(write.func.__self__))
    monkeypatch.setattr(plots.plt, "close", lambda fig: None)
    yield figures
    for fig in figures:
        plt.close(fig)


def _band(label: str, x: list[float], mean: list[float], half: float) -> Band:
    m = np.array(mean)
    return Band(label, np.array(x), m, m - half, m + half)


def test_a_one_budget_arm_shows_its_interval_and_a_one_x_panel_ticks_that_x_alone(drawn, tmp_path):
    one_x = [_band("DOSPCoT", [20.0], [0.7], 0.1), _band("twin", [20.0], [0.5], 0.2)]
    curve = [_band("DOSPCoT", [25.0, 50.0, 100.0, 200.0], [0.2, 0.4, 0.8, 0.9], 0.05)]
    plot_bands({"grid16": one_x, "doorkey": curve}, "labels", "success", tmp_path / "f.png", log_x=True)
    grid16, doorkey = drawn[0].axes
    assert list(grid16.get_xticks()) == [20.0] and grid16.get_xticklabels()[0].get_text() == "20"
    # Each arm's bar spans its interval, the two a little apart around 20.
    bars = [c for c in grid16.containers if c.has_yerr]
    spans = [seg for bar in bars for seg in bar.lines[2][0].get_segments()]
    assert [(s[0][1], s[1][1]) for s in spans] == [pytest.approx((0.6, 0.8)), pytest.approx((0.3, 0.7))]
    assert spans[0][0][0] < 20.0 < spans[1][0][0]
    # A curve keeps its shaded band and ticks its log axis at each x measured, in plain numbers.
    assert not doorkey.containers and doorkey.collections
    assert list(doorkey.get_xticks()) == [25.0, 50.0, 100.0, 200.0]
    assert [label.get_text() for label in doorkey.get_xticklabels()] == ["25", "50", "100", "200"]


def test_a_log_axis_of_many_xs_ticks_1_2_and_5_a_decade_in_plain_numbers(drawn, tmp_path):
    xs = [3.0, 6.0, 12.0, 25.0, 50.0, 100.0, 200.0, 400.0, 800.0]
    plot_bands(
        {"curve": [_band("DOSPCoT", xs, [0.5] * len(xs), 0.1)]}, "labels", "s", tmp_path / "f.png", log_x=True
    )
    ax = drawn[0].axes[0]
    low, high = ax.get_xlim()
    ticks = zip(ax.get_xticklabels(), ax.get_xticks(), strict=True)
    shown = [label.get_text() for label, x in ticks if low <= x <= high]
    assert shown == ["5", "10", "20", "50", "100", "200", "500", "1000"]
