"""``dospcot report``: a sweep's finished runs aggregated per cell, as tables and plots.

A cell is one config with one combination of grid values; its figures are over the cell's seeds, each
seed contributing its run's mean over agents at the last round (``summary.json``). Per cell and metric
the report gives the number of seeds, the mean, the 95% percentile-bootstrap interval of the mean and
the interquartile mean (IQM, as rliable). It writes into the sweep folder (or ``out``):

- ``report.md`` and ``report.csv``: one table per metric; the CSV has one row per cell and metric;
- ``report_per_view.csv`` and the last table of ``report.md``: each view's agent on its own (success,
  greedy return, optimal-action agreement), for the cells whose runs train more than one agent, since
  a mean over agents hides which view's agent failed;
- ``learning_curves.png``: normalised score against env steps per agent, one panel per config,
  one line per cell, a band for the 95% interval over seeds;
- ``pseudo_accuracy.png``: pseudo-reward accuracy against round, likewise (co-training cells only);
- ``score_vs_<key>.png``: the normalised score and success against each numeric grid key (the label
  fraction study), one line per config and remaining grid values.

A sweep of paper-protocol runs (``task = "paper"``, as ``dospcot reproduce-paper`` makes) gets the seed
paper's tables instead (:mod:`dospcot.sweeps.paper_tables`), per cell: ``report.md`` (the target line,
Tables 1-4 for paper accuracy, optimal-action agreement and greedy return, pseudo-reward accuracy and
coverage),
``report.csv`` (long format: one row per table, row, gamma column and metric) and
``paper_agreement.png`` (optimal-action agreement against round, per agent kind and method).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dospcot import metrics
from dospcot.config.choices import method_name
from dospcot.config.run_configs import PaperConfig, TrainConfig
from dospcot.run import paper_protocol as protocol
from dospcot.run.plots import Band, plot_bands
from dospcot.run.run_folder import CONFIG_FILE, METRICS_FILE, SUMMARY_FILE, write_csv, write_text
from dospcot.statistics import SeedSummary
from dospcot.sweeps import paper_tables as paper
from dospcot.sweeps.sweep_spec import TRIAL_FILE, SweepError, SweepSpec, Trial, open_sweep
from dospcot.tasks import load_run_config

REPORT_METRICS = {
    "normalised_score": "normalised score",
    "success": "success",
    "agreement": "optimal-action agreement",
    "pseudo_accuracy": "pseudo-reward accuracy",
    "coverage": "coverage",
}
"""Summary metrics of the report (``summary.json``'s ``mean``), with their titles."""


@dataclass(frozen=True)
class TrialRun:
    """A finished trial: its identity, its ``summary.json``, its ``metrics.csv`` rows and its folder."""

    trial: Trial
    summary: dict[str, Any]
    curves: list[dict[str, float]]
    run_dir: Path


def load_runs(sweep_dir: Path, skipped: list[str] | None = None) -> tuple[SweepSpec, list[TrialRun]]:
    """The sweep's spec and its finished trials, in the sweep's order (config, then grid values).

    :param skipped: where given, a trial whose files cannot be read (a damaged ``summary.json``) is
        left out and named here with the reason, one line each; else it raises.
    :raises SweepError: ``sweep_dir`` is not a sweep folder, or no trial of it has finished.
    """
    spec = open_sweep(sweep_dir, None)
    runs = []
    for trial_path in sweep_dir.glob(f"trials/*/*/{TRIAL_FILE}"):
        if not (trial_path.parent / SUMMARY_FILE).is_file():
            continue
        try:
            trial = Trial.from_dict(json.loads(trial_path.read_text()))
            curves_path = trial_path.parent / METRICS_FILE
            curves = _read_csv(curves_path) if curves_path.is_file() else []
            summary = json.loads((trial_path.parent / SUMMARY_FILE).read_text())
            if not isinstance(summary, dict) or not isinstance(summary.get("mean"), dict):
                raise ValueError(f"{SUMMARY_FILE} holds no table of means")
            if isinstance(summary.get("method"), str):
                summary["method"] = method_name(summary["method"])
        except (OSError, ValueError, KeyError, TypeError) as err:  # JSON and UTF-8 errors are ValueErrors
            if skipped is None:
                raise
            reason = (str(err).splitlines() or [""])[0]
            skipped.append(f"{trial_path.parent}: cannot be read ({type(err).__name__}: {reason})")
            continue
        runs.append(TrialRun(trial, summary, curves, trial_path.parent))
    if not runs:
        raise SweepError(f"{sweep_dir} has no finished trial yet")
    runs.sort(key=lambda run: (*_cell_order(spec, run.trial), run.trial.seed))
    return spec, runs


def _read_csv(path: Path) -> list[dict[str, float]]:
    """The rows of a ``metrics.csv``, numbers as floats and the method by today's name (a record's
    older run spells co-training ``cotrain``)."""
    with path.open(newline="") as handle:
        return [
            {k: method_name(v) if k == "method" else _number(v) for k, v in row.items()}
            for row in csv.DictReader(handle)
        ]


def _number(text: str) -> Any:
    try:
        return float(text)
    except ValueError:
        return text


def _cell_order(spec: SweepSpec, trial: Trial) -> tuple[int, ...]:
    config = spec.configs.index(trial.config) if trial.config in spec.configs else len(spec.configs)
    return (config, *(spec.grid[k].index(v) for k, v in trial.params.items()))


def cells(runs: Sequence[TrialRun]) -> dict[tuple[str, tuple[tuple[str, str], ...]], list[TrialRun]]:
    """The runs grouped by cell: (config name, grid values); insertion order is the sweep's."""
    grouped: dict[tuple[str, tuple[tuple[str, str], ...]], list[TrialRun]] = {}
    for run in runs:
        grouped.setdefault((run.trial.name, tuple(run.trial.params.items())), []).append(run)
    return grouped


PER_VIEW_METRICS = ("success", "greedy_return", "agreement")
"""The per-view table's metrics: each agent's own outcome (``summary.json``'s ``per_view``). The
pseudo-reward figures are left out: the views' agents share their consensus pseudo-rewards."""


def _row(
    name: str, params: tuple, members: Sequence[TrialRun], metric: str, values: list[float], **labels: str
) -> dict[str, Any]:
    stat = SeedSummary.of(values)
    return {
        "config": name,
        **dict(params),
        **labels,
        "metric": metric,
        "n": stat.n,
        "mean": stat.mean,
        "ci_low": stat.low,
        "ci_high": stat.high,
        "iqm": stat.iqm,
        "seeds": " ".join(str(run.trial.seed) for run in members),
    }


def _summary(row: dict[str, Any]) -> SeedSummary:
    """A row of :func:`aggregate` or :func:`aggregate_per_view` back as its summary."""
    return SeedSummary(row["mean"], row["ci_low"], row["ci_high"], row["iqm"], row["n"])


def aggregate(
    runs: Sequence[TrialRun], metrics: Sequence[str] = tuple(REPORT_METRICS)
) -> list[dict[str, Any]]:
    """One row per cell and metric: config, grid values, metric, n, mean, ci_low, ci_high, iqm, seeds."""
    return [
        _row(name, params, members, metric, [run.summary["mean"][metric] for run in members])
        for (name, params), members in cells(runs).items()
        for metric in metrics
    ]


def aggregate_per_view(runs: Sequence[TrialRun]) -> list[dict[str, Any]]:
    """One row per cell of more than one view, per view and per :data:`PER_VIEW_METRICS` metric:
    config, grid values, view, metric, n, mean, ci_low, ci_high, iqm, seeds (over the cell's seeds,
    each seed contributing that view's agent at the last round)."""
    rows = []
    for (name, params), members in cells(runs).items():
        views = list(dict.fromkeys(v for run in members for v in run.summary.get("per_view", {})))
        if len(views) < 2:
            continue
        for view in views:
            holding = [run for run in members if view in run.summary["per_view"]]
            for metric in PER_VIEW_METRICS:
                values = [run.summary["per_view"][view][metric] for run in holding]
                rows.append(_row(name, params, holding, metric, values, view=view))
    return rows


def short_key(key: str) -> str:
    """``training.label_fraction`` -> ``label_fraction``: column titles and plot axes."""
    return key.rsplit(".", 1)[-1]


def _sweep_line(spec: SweepSpec, runs: Sequence[TrialRun]) -> str:
    total = len(spec.configs) * math.prod(len(v) for v in spec.grid.values()) * len(spec.seeds)
    grid = ", ".join(f"{k} = {', '.join(v)}" for k, v in spec.grid.items()) or "none"
    return (
        f"Configs: {', '.join(spec.configs)}; grid: {grid}; seeds: {', '.join(map(str, spec.seeds))} "
        f"({len(runs)} of {total} trials finished)."
    )


def render_markdown(
    spec: SweepSpec,
    runs: Sequence[TrialRun],
    rows: Sequence[dict[str, Any]],
    view_rows: Sequence[dict[str, Any]] = (),
) -> str:
    """``report.md``: a header naming the sweep, one table per metric, then (where ``view_rows``,
    :func:`aggregate_per_view`'s, has any) the per-view table."""
    lines = [
        _sweep_line(spec, runs),
        "Each cell: over seeds, each seed's mean over its agents at the last round; mean "
        "[95% bootstrap interval] and IQM (interquartile mean).",
    ]
    keys = list(spec.grid)
    for metric, title in REPORT_METRICS.items():
        lines += [
            "",
            f"### {title}",
            "",
            "| config | " + "".join(f"{short_key(k)} | " for k in keys) + "seeds | mean [95% CI] | IQM |",
            "|---|" + "---|" * len(keys) + "---|---|---|",
        ]
        for row in (r for r in rows if r["metric"] == metric):
            stat = _summary(row)
            iqm_text = "n/a" if stat.n == 0 else f"{stat.iqm:.3f}"
            lines.append(
                f"| {row['config']} | "
                + "".join(f"{row[k]} | " for k in keys)
                + f"{stat.n} | {stat} | {iqm_text} |"
            )
    if view_rows:
        lines += _per_view_table(keys, view_rows)
    return "\n".join(lines) + "\n"


def _per_view_table(keys: Sequence[str], view_rows: Sequence[dict[str, Any]]) -> list[str]:
    titles = {"greedy_return": "greedy return", **REPORT_METRICS}
    lines = [
        "",
        "### Per view: each agent on its own",
        "",
        "Cells with more than one view only. Each cell: mean over seeds [95% bootstrap interval] of "
        "that view's agent at the last round.",
        "",
        "| "
        + " | ".join(
            ["config", *map(short_key, keys), "view", "seeds", *(titles[m] for m in PER_VIEW_METRICS)]
        )
        + " |",
        "|---|" + "---|" * len(keys) + "---|---|" + "---|" * len(PER_VIEW_METRICS),
    ]
    by_line: dict[tuple, dict[str, dict[str, Any]]] = {}
    for row in view_rows:
        line = (row["config"], *(row[k] for k in keys), row["view"])
        by_line.setdefault(line, {})[row["metric"]] = row
    for (config, *values, view), by_metric in by_line.items():
        stats = [_summary(by_metric[m]) for m in PER_VIEW_METRICS]
        columns = [config, *map(str, values), view, str(stats[0].n), *map(str, stats)]
        lines.append("| " + " | ".join(columns) + " |")
    return lines


def round_bands(members: Sequence[TrialRun], metric: str, x_key: str) -> Band | None:
    """Per round, the mean over seeds (of each seed's mean over views) and its 95% bootstrap band."""
    per_seed: dict[float, list[float]] = {}
    for run in members:
        for round_ in sorted({row["round"] for row in run.curves}):
            rows = [row for row in run.curves if row["round"] == round_]
            value = float(np.mean([row[metric] for row in rows]))
            if math.isfinite(value):
                per_seed.setdefault(rows[0][x_key], []).append(value)
    if not per_seed:
        return None
    return _band("", {x: SeedSummary.of(values) for x, values in per_seed.items()})


def _band(label: str, points: dict[float, SeedSummary]) -> Band:
    xs = sorted(points)
    mean, low, high = (np.array([getattr(points[x], field) for x in xs]) for field in ("mean", "low", "high"))
    return Band(label, np.array(xs), mean, low, high)


def write_report(
    sweep_dir: Path, out_dir: Path | None = None, skipped: list[str] | None = None
) -> list[Path]:
    """Write the sweep's report, the one of its kind of config (:data:`REPORT_WRITERS`); return the
    files. ``skipped``: as :func:`load_runs`'s."""
    spec, runs = load_runs(sweep_dir, skipped)
    out_dir = out_dir or sweep_dir
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise SweepError(f"--out {out_dir}: cannot make the folder ({err.strerror or err})") from None
    # A sweep holds one kind of config (SweepSpec.trials), which decides its report.
    kind = type(load_run_config(runs[0].run_dir / CONFIG_FILE))
    return REPORT_WRITERS[kind](spec, runs, out_dir)


def write_cotraining_report(spec: SweepSpec, runs: Sequence[TrialRun], out_dir: Path) -> list[Path]:
    """A sweep of co-training runs: ``report.md``, ``report.csv``, ``report_per_view.csv`` where a cell
    has several views, and the plots."""
    rows, view_rows = aggregate(runs), aggregate_per_view(runs)
    written = [out_dir / "report.md", out_dir / "report.csv"]
    write_text(written[0], render_markdown(spec, runs, rows, view_rows))
    write_csv(written[1], rows)
    if view_rows:
        written.append(out_dir / "report_per_view.csv")
        write_csv(written[-1], view_rows)
    grouped = cells(runs)
    for metric, x_key, name in (
        ("normalised_score", "env_steps", "learning_curves.png"),
        ("pseudo_accuracy", "round", "pseudo_accuracy.png"),
    ):
        panels: dict[str, list[Band]] = {}
        for (config, params), members in grouped.items():
            band = round_bands(members, metric, x_key)
            if band is not None:
                label = ", ".join(f"{short_key(k)}={v}" for k, v in params) or config
                panels.setdefault(config, []).append(band.labelled(label))
        if panels:
            xlabel = "env steps per agent" if x_key == "env_steps" else "round"
            plot_bands(panels, xlabel, REPORT_METRICS[metric], out_dir / name)
            written.append(out_dir / name)
    for key in spec.grid:
        path = _plot_against(key, spec, grouped, out_dir)
        if path is not None:
            written.append(path)
    return written


AGAINST_METRICS = ("normalised_score", "success")
"""The panels of ``score_vs_<key>.png``: the score, and success, which the score can hide."""


def _plot_against(key: str, spec: SweepSpec, grouped: dict, out_dir: Path) -> Path | None:
    """The normalised score and success against a numeric grid key, one line per config and other
    grid values."""
    try:
        values = [float(v) for v in spec.grid[key]]
    except ValueError:
        return None
    panels: dict[str, list[Band]] = {}
    for metric in AGAINST_METRICS:
        lines: dict[str, dict[float, SeedSummary]] = {}
        for (config, params), members in grouped.items():
            others = ", ".join(f"{short_key(k)}={v}" for k, v in params if k != key)
            label = f"{config} ({others})" if others else config
            stat = SeedSummary.of([run.summary["mean"][metric] for run in members])
            if stat.n:
                lines.setdefault(label, {})[float(dict(params)[key])] = stat
        if lines:
            panels[REPORT_METRICS[metric]] = [_band(label, points) for label, points in lines.items()]
    if not panels:
        return None
    log_x = min(values) > 0 and max(values) / min(values) >= 20
    path = out_dir / f"score_vs_{short_key(key)}.png"
    xlabel = short_key(key).replace("_", " ")
    plot_bands(panels, xlabel, "mean over seeds", path, log_x=log_x, markers=True, share_y=False)
    return path


def paper_report_tables(runs: Sequence[TrialRun], level: int = 2) -> tuple[list[str], list[dict[str, Any]]]:
    """The seed paper's tables over the seeds of each cell of a sweep of paper-protocol runs: the
    markdown lines (headings from ``level``; a heading per cell when there are several) and the long
    rows of ``report.csv``."""
    grouped = cells(runs)
    lines: list[str] = []
    rows: list[dict[str, Any]] = []
    for (name, params), members in grouped.items():
        cfg = load_run_config(members[0].run_dir / CONFIG_FILE)
        records = [row for run in members for row in run.curves]
        table = paper.build_tables(records, metrics.published_paper_tables(), cfg.tabular.rounds)
        seeds = [run.trial.seed for run in members]
        if len(grouped) > 1:
            lines += [f"{'#' * level} {_cell_title(name, params)}", ""]
        lines += paper.render_tables(table, paper.target_check(table), cfg, seeds, level + (len(grouped) > 1))
        rows += [{"config": name, **dict(params), **row} for row in table]
    return lines, rows


def _cell_title(name: str, params: tuple[tuple[str, str], ...]) -> str:
    return ", ".join([name, *(f"{short_key(k)}={v}" for k, v in params)])


def write_paper_report(spec: SweepSpec, runs: Sequence[TrialRun], out_dir: Path) -> list[Path]:
    """A sweep of paper-protocol runs: the seed paper's tables over seeds and the agreement plots."""
    info = [json.loads((run.run_dir / "run_info.json").read_text()) for run in runs]
    lines, rows = paper_report_tables(runs)
    header = [
        "# Seed paper reproduction: masked CliffWalking-v1",
        "",
        _sweep_line(spec, runs) + "  ",
        f"Training: {sum(i['wall_time_s'] for i in info):.1f} s of wall time summed over trials (a batch of "
        f"seeds trained together splits its time evenly), on {info[0]['machine']}, Python "
        f"{info[0]['python']}.",
        "",
    ]
    written = [out_dir / "report.md", out_dir / "report.csv"]
    write_text(written[0], "\n".join(header + lines))
    write_csv(written[1], rows)
    for index, ((name, params), members) in enumerate(cells(runs).items()):
        path = out_dir / ("paper_agreement.png" if index == 0 else f"paper_agreement_{index}.png")
        _plot_paper_agreement([row for run in members for row in run.curves], _cell_title(name, params), path)
        written.append(path)
    return written


def _plot_paper_agreement(records: list[dict[str, Any]], title: str, path: Path) -> None:
    """Optimal-action agreement against round, one panel per agent kind: its baselines and its
    DOSPCoT pair at gamma 0.3 (each a band over seeds)."""
    values = protocol.per_seed(records, "agreement")
    rounds = sorted({int(record["round"]) for record in records})
    panels: dict[str, list[Band]] = {}
    for kind in protocol.KINDS:
        lines = {label: (method, kind, view, 0.3) for label, method, view in protocol.BASELINES}
        lines["DOSPCoT (γ 0.3)"] = ("dospcot", f"{kind}-{kind}", "-".join(protocol.PAIR_VIEWS), 0.3)
        panels[f"{title}: {protocol.KIND_NAMES[kind]}"] = [
            _band(label, {r: SeedSummary.of(values[(*key, r)]) for r in rounds})
            for label, key in lines.items()
        ]
    plot_bands(panels, "round", "optimal-action agreement", path, markers=True)


REPORT_WRITERS: dict[type, Callable[[SweepSpec, Sequence[TrialRun], Path], list[Path]]] = {
    TrainConfig: write_cotraining_report,
    PaperConfig: write_paper_report,
}
"""The report of a sweep of each kind of config: the co-training tables of every task but the paper's,
whose sweeps get the seed paper's tables."""
