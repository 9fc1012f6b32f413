"""The pre-registered second-view study (docs/preregistration.md): when does a second view help? Its
grid settings (independent and identical blind spots, a monitor) and its fast-highway monitor, the
paired differences and each hypothesis's verdict."""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from functools import partial

import numpy as np

from dospcot.config.choices import method_name
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.highway_studies import HIGHWAY_COLUMNS
from dospcot_lab.studies.tables import (
    COLUMNS,
    FRACTION,
    GRID16_PRESETS,
    LABELS_COLUMN,
    LABELS_EXPLAINED,
    labels_cell,
    over_seeds,
    paired,
    run_value,
)

# The second-view study (docs/preregistration.md, committed before any of its runs): its settings,
# seeds, metrics, test and smallest effects are that file's; nothing here may differ from it.
SECOND_VIEW_SETTINGS: dict[str, dict[str, str]] = {
    "independent errors": {"env.blind_spot_rate": "0.5", "env.blind_spots": "independent"},
    "identical errors": {"env.blind_spot_rate": "0.5", "env.blind_spots": "identical"},
    "monitor": {"env.monitored_columns": "8", FRACTION: "0.02"},
    "highway monitor": {"highway.reveal_first_steps": "10", FRACTION: "0.02"},
}
SMALLEST_EFFECT = {"pseudo_accuracy": 0.01, "success": 0.1}
"""The smallest paired difference that counts (H1), by metric."""
SECOND_VIEW_COLUMNS = (
    "success",
    "pseudo_accuracy",
    "agreement",
    "worst_class_precision",
    "worst_class_recall",
    "normalised_score",
)
"""The primary metrics, then the secondary ones the pre-registration names (its amendment of 2026-11-26
says why the worst class's precision and recall stand for the lava class's)."""
HIGHWAY_SECOND_VIEW_COLUMNS = ("greedy_return", "success", "pseudo_accuracy", "normalised_score")
AGENT_WORDS = {"dqn": "neural (DQN)", "tabular": "tabular"}


def _setting(run: TrialRun) -> str:
    """The second-view setting whose keys a run's grid values hold."""
    params = run.trial.params
    return next(
        name
        for name, keys in SECOND_VIEW_SETTINGS.items()
        if all(params.get(k) == v for k, v in keys.items())
    )


def _method(run: TrialRun) -> str:
    """A run's method in the second-view tables; self-training and single-view baselines name their view."""
    name = method_name(run.trial.params.get("method") or run.trial.name.split("-", 1)[1])
    views = json.loads(run.trial.params["views"]) if "views" in run.trial.params else None
    return f"{name} ({views[0]})" if views else name


def _by_seed(runs: list[TrialRun]) -> dict[str, dict[tuple[str, str], dict[int, TrialRun]]]:
    """setting -> (agent kind, method) -> seed -> run."""
    table: dict[str, dict[tuple[str, str], dict[int, TrialRun]]] = {}
    for run in runs:
        agent = run.trial.params.get("agent", "dqn")
        table.setdefault(_setting(run), {}).setdefault((agent, _method(run)), {})[run.trial.seed] = run
    return table


def _better_view(methods: dict[str, dict[int, TrialRun]], method: str, metric: str) -> str | None:
    """Of ``method``'s rows (one per view, or one), the one with the higher mean over seeds of
    ``metric``: the comparison then favours that method."""
    means = {
        name: float(np.nanmean([run_value(r, metric) for r in seeds.values()]))
        for name, seeds in methods.items()
        if name == method or name.startswith(f"{method} (")
    }
    return max(means, key=means.__getitem__) if means else None


def _verdict(ok: bool | None) -> str:
    return "not yet run" if ok is None else ("**confirmed**" if ok else "**not confirmed**")


SECOND_VIEW_ORDER = ("oracle", "masked-zero", "labels-only", "self-training", "dospcot", "m3")
SECOND_VIEW_WORDS = {"dospcot": "DOSPCoT (m = 2)", "m3": "m = 3 (+ coords, error-free)"}


def _cells(
    runs: list[TrialRun], columns: tuple[str, ...]
) -> Iterator[tuple[str, str, dict[str, dict[int, TrialRun]], Hypothesis]]:
    """Per setting and agent kind: the setting, the kind, its methods' runs by seed and the test of its
    hypothesis."""
    titles = _titles(columns)
    for setting, by_method in _by_seed(runs).items():
        for agent in sorted({agent for agent, _ in by_method}):
            methods = {m: seeds for (a, m), seeds in by_method.items() if a == agent}
            yield setting, agent, methods, _hypothesis(setting, methods, columns[0], titles)


def _titles(columns: tuple[str, ...]) -> dict[str, str]:
    return {
        **COLUMNS,
        "worst_class_recall": "worst-class recall",
        **(HIGHWAY_COLUMNS if "greedy_return" in columns else {}),
    }


def second_view_tables(runs: list[TrialRun], columns: tuple[str, ...] = SECOND_VIEW_COLUMNS) -> list[str]:
    """Per setting and agent kind: every method's metrics over seeds, then the pre-registered paired
    differences and each hypothesis marked confirmed or not (docs/preregistration.md)."""
    titles = _titles(columns)
    lines = [LABELS_EXPLAINED]
    for setting, agent, methods, hypothesis in _cells(runs, columns):
        lines += [
            "",
            f"**{setting}, {AGENT_WORDS[agent]} agents**",
            "",
            "| method | " + " | ".join([*(titles[c] for c in columns), LABELS_COLUMN]) + " |",
            "|---|" + "---|" * (len(columns) + 1),
        ]
        for method in sorted(methods, key=lambda m: (SECOND_VIEW_ORDER.index(m.split(" (")[0]), m)):
            members = list(methods[method].values())
            cells = [*(over_seeds(members, c) for c in columns), labels_cell(members)]
            lines.append(f"| {SECOND_VIEW_WORDS.get(method, method)} | " + " | ".join(cells) + " |")
        lines += ["", *hypothesis.lines]
    return lines


def second_view_glance(runs: list[TrialRun], columns: tuple[str, ...] = SECOND_VIEW_COLUMNS) -> Glance:
    """The first setting's paired differences on the neural agents, and every hypothesis's verdict per
    agent kind."""
    verdicts: dict[str, list[str]] = {}
    first = None
    for _, agent, _, hypothesis in _cells(runs, columns):
        first = first or hypothesis
        words = AGENT_WORDS[agent].split(" (")[0]
        verdicts.setdefault(f"{hypothesis.name} {_verdict(hypothesis.ok).replace('*', '')}", []).append(words)
    assert first is not None  # a study with runs has a setting
    headline = f"{first.name}: " + "; ".join(f"{label}: {diff}" for label, diff in first.differences)
    return Glance(headline, "; ".join(f"{v} ({', '.join(kinds)})" for v, kinds in verdicts.items()))


@dataclass(frozen=True)
class Hypothesis:
    """The test of a setting's hypothesis: its name (H1-H3), verdict (None: not yet run), the paired
    differences it rests on (what each is, and the difference) and the table lines that say so."""

    name: str
    ok: bool | None
    differences: tuple[tuple[str, SeedSummary], ...]
    lines: tuple[str, ...]


def _hypothesis(
    setting: str, methods: dict[str, dict[int, TrialRun]], outcome: str, titles: dict[str, str]
) -> Hypothesis:
    """The paired differences of a setting and the verdict of its hypothesis; under a monitor, also
    DOSPCoT minus the better self-training view, which no hypothesis tests there."""
    lines, verdicts, differences = [], [], []
    if setting in ("monitor", "highway monitor"):
        zero = _better_view(methods, "masked-zero", outcome)
        best = _better_view(methods, "self-training", outcome)
        for name, seeds in ((best, methods.get(best or "")), ("DOSPCoT", methods.get("dospcot"))):
            if seeds is None or zero is None:
                verdicts.append(None)
                continue
            diff = paired(seeds, methods[zero], outcome)
            lines.append(f"- {titles[outcome]}, {name} minus {zero} (paired by seed): {diff}")
            differences.append((f"{titles[outcome]}, {name} minus {zero}", diff))
            verdicts.append(diff.low > 0)
        ok = None if None in verdicts else all(verdicts)
        lines.append(f"- H3 (masked-zero below self-training and DOSPCoT): {_verdict(ok)}")
        for metric in ("pseudo_accuracy", outcome):
            if (found := _versus_self_training(methods, metric, titles)) is not None:
                lines.append(found[0] + " (no hypothesis)")
        return Hypothesis("H3", ok, tuple(differences), tuple(lines))
    for metric in ("pseudo_accuracy", "success"):
        found = _versus_self_training(methods, metric, titles)
        if found is None:
            verdicts.append(None)
            continue
        line, diff = found
        lines.append(line)
        differences.append((f"{titles[metric]}, DOSPCoT minus the better self-training view", diff))
        if setting == "independent errors":
            verdicts.append(diff.low > 0 and diff.mean >= SMALLEST_EFFECT[metric])
        else:
            verdicts.append(diff.low <= 0 <= diff.high)
    ok = None if None in verdicts else all(verdicts)
    if setting == "independent errors":
        lines.append(f"- H1 (DOSPCoT above the better self-training view in both): {_verdict(ok)}")
        return Hypothesis("H1", ok, tuple(differences), tuple(lines))
    lines.append(f"- H2 (no difference: both intervals hold 0): {_verdict(ok)}")
    return Hypothesis("H2", ok, tuple(differences), tuple(lines))


def _versus_self_training(
    methods: dict[str, dict[int, TrialRun]], metric: str, titles: dict[str, str]
) -> tuple[str, SeedSummary] | None:
    """``metric`` of DOSPCoT minus the better self-training view, paired by seed, as a line and the
    difference; None while either has not run."""
    best = _better_view(methods, "self-training", metric)
    dospcot = methods.get("dospcot")
    if best is None or dospcot is None:
        return None
    diff = paired(dospcot, methods[best], metric)
    return f"- {titles[metric]}, DOSPCoT minus {best} (the better view, paired by seed): {diff}", diff


def _second_view_sweeps() -> tuple[Sweep, ...]:
    """Per grid setting: the presets with neural and tabular agents, and self-training on each view."""
    presets = tuple(p for p in GRID16_PRESETS if p != "grid16-self-training")
    views = {"views": ('["patch"]', '["rays"]')}
    sweeps = []
    for setting in ("independent errors", "identical errors", "monitor"):
        keys = SECOND_VIEW_SETTINGS[setting]
        grid = {**{key: (value,) for key, value in keys.items()}, "agent": ("dqn", "tabular")}
        slug = setting.split()[0]
        sweeps.append(Sweep(f"second-view-{slug}", presets, grid))
        sweeps.append(
            Sweep(f"second-view-{slug}-self-training", ("grid16-self-training",), {**grid, **views})
        )
    return tuple(sweeps)


def _second_view_highway_sweeps() -> tuple[Sweep, ...]:
    """The fast highway under the monitor: every single-view method on each view (the oracle per view
    is the control the highway study lacks), labels-only from the masked-zero preset, and DOSPCoT."""
    grid = {key: (value,) for key, value in SECOND_VIEW_SETTINGS["highway monitor"].items()}
    per_view = {**grid, "views": ('["kinematics"]', '["occupancy"]')}
    singles = ("fasthighway-oracle", "fasthighway-masked-zero", "fasthighway-self-training")
    return (
        Sweep("second-view-highway-single", singles, per_view),
        Sweep(
            "second-view-highway-labels-only",
            ("fasthighway-masked-zero",),
            {**per_view, "method": ("labels-only",)},
        ),
        Sweep("second-view-highway-dospcot", ("fasthighway-dospcot",), grid),
    )


STUDIES: dict[str, Study] = {
    "second-view": Study(
        _second_view_sweeps(),
        second_view_tables,
        "When does a second view help? (grid)",
        "16 x 16 grid: blind spots, a reward monitor",
        second_view_glance,
        seeds=10,
        confirmatory=True,
    ),
    "second-view-highway": Study(
        _second_view_highway_sweeps(),
        partial(second_view_tables, columns=HIGHWAY_SECOND_VIEW_COLUMNS),
        "When does a second view help? (fast highway)",
        "our fast highway: a reward monitor",
        partial(second_view_glance, columns=HIGHWAY_SECOND_VIEW_COLUMNS),
        confirmatory=True,
    ),
}
