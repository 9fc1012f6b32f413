"""What the studies' tables share: the presets' names in words, the metric columns, and the cells over
seeds (a method's runs, a view's agents, two arms paired by seed, the labels an arm used)."""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Callable, Collection, Sequence
from typing import Any

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun, cells
from dospcot_lab.studies.declaration import NOT_MEASURED, Glance

GRID_METHODS = {
    "oracle": "oracle",
    "masked-zero": "masked-zero",
    "labels-only": "labels-only",
    "self-training": "self-training",
    "dospcot": "DOSPCoT",
    "m3": "m = 3",
}
METHODS = {
    **{f"{grid}-{method}": label for grid in ("grid16", "grid32") for method, label in GRID_METHODS.items()},
    **{
        f"{base}-{method}": label
        for base in ("highway", "fasthighway")
        for method, label in {
            "oracle": "oracle",
            "masked-zero": "masked-zero",
            "self-training": "self-training",
            "dospcot": "DOSPCoT",
        }.items()
    },
}
MINIGRID_TASKS = {"lavagap": "MiniGrid-LavaGapS7-v0", "doorkey": "MiniGrid-DoorKey-5x5-v0"}
METHODS.update(
    {
        f"minigrid-{task}-{method}": label
        for task in MINIGRID_TASKS
        for method, label in {
            "oracle": "oracle",
            "masked-zero": "masked-zero",
            "self-training": "self-training",
            "dospcot": "DOSPCoT",
        }.items()
    }
)
COLUMNS = {
    "success": "success",
    "agreement": "optimal-action agreement",
    "normalised_score": "normalised score",
    "pseudo_accuracy": "pseudo-reward accuracy",
    "worst_class_precision": "worst-class precision",
    "coverage": "coverage",
}
FRACTION = "training.label_fraction"
LABELS_COLUMN = "labels used per run"
LABELS_EXPLAINED = (
    "Labels used per run: the labelled samples a run held at its end (those its agents met whose reward "
    "its mask, a monitor or a demonstration revealed, or the answers it bought), mean over its seeds; "
    "the oracle reads every reward."
)
"""What :func:`labels_cell` counts, for the tables that show it beside their cells over seeds."""
GRID16_PRESETS = tuple(name for name in METHODS if name.startswith("grid16-"))


def by_method(runs: list[TrialRun]) -> dict[tuple[str, tuple], list[TrialRun]]:
    """The sweep cells in the order of :data:`METHODS`, then by rounds."""
    order = list(METHODS)
    return dict(
        sorted(cells(runs).items(), key=lambda item: (order.index(item[0][0]), item[1][0].summary["rounds"]))
    )


def cell_labels(grouped: dict[tuple[str, tuple], list[TrialRun]]) -> dict[tuple[str, tuple], str]:
    """Each cell's method, in words; with its rounds where the cells differ in them."""
    rounds = {key: members[0].summary["rounds"] for key, members in grouped.items()}
    with_rounds = len(set(rounds.values())) > 1
    suffix = {key: f", {n} rounds" if with_rounds else "" for key, n in rounds.items()}
    return {key: METHODS.get(key[0], key[0]) + suffix[key] for key in grouped}


def views_line(grouped: dict[tuple[str, tuple], list[TrialRun]]) -> str:
    """The views each method's agents see, once per method, for the tables that name methods short."""
    seen = dict.fromkeys(
        f"{METHODS.get(name, name)}: {' + '.join(members[0].summary['views'])}"
        for (name, _), members in grouped.items()
    )
    return f"Each method's views: {'; '.join(seen)}."


def over_seeds(members: list[TrialRun], key: str, view: str | None = None) -> str:
    """A metric over the seeds of a cell, of the run mean or (``view``) of one view's agent."""
    # Runs written before a metric existed read NaN there, which the summary leaves out.
    return str(
        SeedSummary.of(
            [(r.summary["per_view"][view] if view else r.summary["mean"]).get(key, math.nan) for r in members]
        )
    )


def per_view_rows(
    grouped: dict[tuple[str, tuple], list[TrialRun]],
    keys: list[str],
    first: Callable[[str], str] | None = None,
) -> list[str]:
    """One table row per method and view: ``keys`` over seeds, then the labels each run used (every
    agent of a run reads the same); ``first`` gives a leading cell from the preset's name (a task
    column)."""
    labels = cell_labels(grouped)
    return [
        ("" if first is None else f"| {first(key[0])} ")
        + f"| {labels[key]} | {view} | "
        + " | ".join([*(over_seeds(members, k, view) for k in keys), labels_cell(members)])
        + " |"
        for key, members in grouped.items()
        for view in members[0].summary["views"]
    ]


def mean_over_oracles(grouped: dict[tuple[str, tuple], list[TrialRun]], metric: str) -> float:
    """``metric``'s mean over the seeds of the oracle cells (NaN without one)."""
    values = [r.summary["mean"][metric] for (n, _), m in grouped.items() if n.endswith("-oracle") for r in m]
    return SeedSummary.of(values).mean if values else math.nan


def run_value(run: TrialRun, metric: str) -> float:
    """A run's mean over its agents of ``metric``; NaN where the run did not record it."""
    return run.summary["mean"].get(metric, math.nan)


def labels_used(run: TrialRun) -> float:
    """The labels a run held at its end (bought answers, or its mask's share), mean over its agents
    (every agent of a run reads the same labels); NaN where the run did not count them."""
    return float(run.summary["mean"].get("labelled_steps", math.nan))


def labels_cell(members: list[TrialRun]) -> str:
    """The labels each run of ``members`` used (:func:`labels_used`), mean over the runs that counted
    them: "every reward" for an oracle's runs, "unknown" where no run counted them, "n/a" for none."""
    if not members:
        return "n/a"
    # Presets name their method last; an oracle's pool counts the samples met, all of them labelled.
    if all(run.trial.config.endswith("-oracle") for run in members):
        return "every reward"
    known = [used for run in members if not math.isnan(used := labels_used(run))]
    return f"{sum(known) / len(known):,.0f}" if known else "unknown"


def numerics_of(run: TrialRun) -> int:
    """The numerics version of the run's classifier fits, as its ``run_info.json`` names it (1 for runs
    written before versions were named: they all fit in numerics 1)."""
    info = run.run_dir / "run_info.json"
    return int(json.loads(info.read_text()).get("numerics", 1)) if info.is_file() else 1


def cpu_seconds(run: TrialRun) -> float | None:
    """The CPU seconds a run's ``run_info.json`` recorded (a batch member's share), None where none."""
    return json.loads((run.run_dir / "run_info.json").read_text()).get("cpu_time_s")


def cpu_per_run(runs: list[TrialRun]) -> str:
    """The CPU time per run over ``runs`` (each run's ``cpu_time_s``; a batch member's share)."""
    known = [s for s in map(cpu_seconds, runs) if s is not None]
    return f"{sum(known) / len(known):.0f} CPU-s" if known else "unknown"


ADOPTION_METRICS = {"success": "success", "pseudo_accuracy": "pseudo-reward accuracy"}
"""The metrics the adoption rule holds a new default to (:func:`non_inferior`), with their headings."""

CLASS_RECALL = {"worst_class_recall": "worst-class recall"}
"""Shown beside the adoption rule's metrics, outside the rule: accuracy is dominated by the commonest
class, and a rare class (a goal no label showed) can be missed at an accuracy near 1."""
CLASS_RECALL_NOTE = (
    "Worst-class recall, beside the rule's metrics and outside the rule: of the reward class least often "
    "given its reward, the share of its samples given it (last round; 0 where no label showed a class). "
    "Accuracy counts every sample, so the commonest class fills it."
)
"""The sentence under a table with a :data:`CLASS_RECALL` column."""


def version_rows(
    members_of: Callable[[str, int], list[TrialRun]],
    presets: Sequence[str],
    versions: Sequence[int],
    kind: str,
    columns: dict[str, str],
) -> list[str]:
    """A table of a study comparing versions (of the defaults, of the numerics): per preset and
    version whose runs ``members_of(preset, version)`` gives, each metric of ``columns`` (metric ->
    its heading) over the seeds, the CPU time per run and the seeds; ``kind`` heads the version's
    column. A preset and version with no run has no row."""
    lines = [
        f"| preset | {kind} | {' | '.join(columns.values())} | CPU time per run | seeds |",
        "|---|---|" + "---|" * (len(columns) + 2),
    ]
    for preset in presets:
        for version in versions:
            members = members_of(preset, version)
            if members:
                cells = [*(over_seeds(members, metric) for metric in columns), cpu_per_run(members)]
                lines.append(f"| `{preset}` | {version} | {' | '.join(cells)} | {len(members)} |")
    return lines


def seeds_to_clear(differences: Sequence[float], margin: float, power: float = 0.8) -> int | None:
    """Seeds a paired comparison needs so that, where the true difference is 0, its 95% interval's lower
    end lies above ``-margin`` in ``power`` of such studies, from the spread of ``differences`` (one per
    seed): ``ceil(((z_0.975 + z_power) * sd / margin) ** 2)``, under the normal approximation (the
    half-width is 1.96 standard errors, and the mean must land above ``half-width - margin``), and at
    least 2 (an interval needs two). None from fewer than two differences."""
    if len(differences) < 2:
        return None
    z = statistics.NormalDist().inv_cdf
    return max(2, math.ceil(((z(0.975) + z(power)) * statistics.stdev(differences) / margin) ** 2))


def paired(
    a: dict[int, TrialRun],
    b: dict[int, TrialRun],
    metric: str,
    across_numerics: bool = False,
    value: Callable[[TrialRun], float] | None = None,
) -> SeedSummary:
    """``metric`` of a minus b, paired by seed: mean and 95% bootstrap interval over the seeds both ran.

    :param across_numerics: compare runs of different numerics versions (only the study that compares
        the versions does); otherwise such a comparison is refused.
    :param value: a run's figure, where it is not its mean over agents of ``metric`` (:func:`run_value`;
        ``metric`` then names it in the error).
    :raises ValueError: the runs compared were trained under more than one numerics version.
    """
    return SeedSummary.of(paired_differences(a, b, metric, across_numerics, value))


def paired_differences(
    a: dict[int, TrialRun],
    b: dict[int, TrialRun],
    metric: str,
    across_numerics: bool = False,
    value: Callable[[TrialRun], float] | None = None,
) -> list[float]:
    """:func:`paired`'s differences, a minus b, one per seed both ran, in seed order (its parameters and
    its error)."""
    figure = value or (lambda run: run_value(run, metric))
    seeds = sorted(set(a) & set(b))
    versions = {numerics_of(r) for s in seeds for r in (a[s], b[s])}
    if len(versions) > 1 and not across_numerics:
        raise ValueError(
            f"a comparison of {metric} mixes runs of numerics versions {sorted(versions)}: train every arm "
            "under one version (cotraining.numerics) before comparing them"
        )
    return [figure(a[s]) - figure(b[s]) for s in seeds]


def held_lines(
    differences: dict[str, dict[str, SeedSummary]], held: Callable[[SeedSummary], bool], bound: str
) -> list[str]:
    """One line per preset and metric of ``differences`` (paired differences over seeds): the
    difference, the ``bound`` (in words) it is held to, and whether ``held`` says it holds."""
    return [
        f"- `{preset}` {metric}: {diff} over {diff.n} seeds; {bound}: "
        + ("**held**" if held(diff) else "**not met**")
        + "."
        for preset, by_metric in differences.items()
        for metric, diff in by_metric.items()
        if diff.n
    ]


NON_INFERIORITY_MARGIN = 0.05
"""How far below 0 the lower end of a paired difference's 95% interval (new minus old) may lie for a
new default to replace an old one: non-inferiority, not equivalence, since a change may improve."""


NON_INFERIOR_WORDS = f"non-inferior where the interval's lower end lies above -{NON_INFERIORITY_MARGIN}"
"""The adoption rule for a default, in words, for the lines of :func:`held_lines`."""


def non_inferior(diff: SeedSummary, margin: float = NON_INFERIORITY_MARGIN) -> bool:
    """Whether the paired difference new minus old shows the new no worse than ``margin``: the lower
    end of its 95% interval lies above ``-margin``."""
    return diff.n > 0 and diff.low > -margin


ADOPTION_SEEDS = 20
"""The paired seeds per preset the adoption rule names: a preset with fewer decides nothing yet."""


def measured_presets(differences: dict[str, dict[str, SeedSummary]]) -> list[str]:
    """The presets of ``differences`` (preset -> metric -> paired difference) that hold the
    :data:`ADOPTION_SEEDS` pairs the adoption rule names, in their order."""
    return [preset for preset, by_metric in differences.items() if by_metric["success"].n >= ADOPTION_SEEDS]


def _fails(by_metric: dict[str, SeedSummary]) -> bool:
    """Whether a preset's differences (metric -> paired difference) fail the adoption rule."""
    return not all(non_inferior(d) for d in by_metric.values())


def deciding_preset(differences: dict[str, dict[str, SeedSummary]]) -> str | None:
    """The preset a study's headline names: the first measured one where a difference is not
    non-inferior (it decides the verdict), else the last measured; None where none is measured."""
    measured = measured_presets(differences)
    return next((p for p in measured if _fails(differences[p])), measured[-1] if measured else None)


BEST_VALUE = {"success": 1.0, "pseudo_accuracy": 1.0}
"""The most each metric of the adoption rule can read: both are shares."""


def best_case(new: dict[int, TrialRun], old: dict[int, TrialRun], metric: str) -> SeedSummary:
    """``metric`` of new minus old, paired by seed over the :data:`ADOPTION_SEEDS` seeds old ran, each
    seed new has not run yet read at the most it could show (:data:`BEST_VALUE`); no seed where old
    holds fewer. Whatever those seeds show, no end of the real interval can lie above this one's: the
    bootstrap's resamples are fixed by its own seed, and each resampled mean grows with every value."""
    seeds = sorted(old)[:ADOPTION_SEEDS]
    if len(seeds) < ADOPTION_SEEDS:
        return SeedSummary.of([])
    best = BEST_VALUE[metric]
    return SeedSummary.of(
        [(run_value(new[s], metric) if s in new else best) - run_value(old[s], metric) for s in seeds]
    )


def adoption_glance(
    differences: dict[str, dict[str, SeedSummary]],
    change: str,
    verdicts: tuple[str, str, str],
    decided_early: Collection[str] = (),
) -> Glance:
    """The row of a study that decides a default: its headline, ``change`` in success on the preset that
    decides (:func:`deciding_preset`), and its verdict by :func:`non_inferior` over every measured
    difference. A preset counts as measured once it holds the :data:`ADOPTION_SEEDS` pairs the rule
    names: a verdict on fewer would be read off a part of the sample, unless no outcome of the pairs it
    lacks could meet the rule (``decided_early``, :func:`best_case`).

    :param differences: preset -> metric -> the paired difference, new minus old.
    :param change: the comparison in words (``"numerics 2 minus 1"``).
    :param verdicts: what to say where a difference is not non-inferior, where every measured one is
        but a preset is not measured yet, and where every one on every preset is.
    :param decided_early: the presets, short of their pairs, that fail the rule whatever those show.
    """
    measured = measured_presets(differences)
    early = [p for p in differences if p in decided_early and p not in measured]
    if not measured and not early:
        return Glance(f"{change}: {NOT_MEASURED}", NOT_MEASURED)
    failing = [p for p in differences if p in early or (p in measured and _fails(differences[p]))]
    preset = failing[0] if failing else measured[-1]
    if failing:
        verdict = verdicts[0]
    elif len(measured) < len(differences):
        verdict = verdicts[1]
    else:
        verdict = verdicts[2]
    success = differences[preset]["success"]
    headline = f"{preset} success, {change}, paired by seed: {success}"
    if preset in early:
        left = ADOPTION_SEEDS - success.n
        headline += f" over {success.n} seeds (the rule fails whatever the other {left} show)"
    return Glance(headline, verdict)


def verdict(diff: SeedSummary, ours: str = "DOSPCoT", theirs: str = "self-training") -> str:
    """What a paired difference ``ours`` minus ``theirs`` shows: one above the other where its 95%
    interval excludes 0, else no difference."""
    if diff.n == 0:
        return "not run"
    if diff.low > 0:
        return f"{ours} above {theirs}"
    if diff.high < 0:
        return f"{ours} below {theirs}"
    return "no difference shown (the interval holds 0)"


def versus(
    runs: list[TrialRun],
    ours: str,
    theirs: str,
    metric: str,
    key: Callable[[TrialRun], Any] = lambda run: run.trial.seed,
) -> SeedSummary:
    """``metric`` of the runs of preset ``ours`` minus those of ``theirs``, paired by ``key`` (the
    seed; on several maps, the map and the seed)."""
    a, b = ({key(r): r for r in runs if r.trial.name == name} for name in (ours, theirs))
    return paired(a, b, metric)


def glance_versus(
    runs: list[TrialRun], prefix: str, metric: str, paired_by: str = "seed", labels: bool = False, **kwargs
) -> Glance:
    """The usual headline: ``metric``, DOSPCoT minus self-training (the presets ``<prefix>-dospcot``
    and ``<prefix>-self-training``), paired by seed, with its verdict; with ``labels``, the labels a
    run of each held (where a mask labels a share of the steps met, two agents meet twice the steps)."""
    a, b = f"{prefix}-dospcot", f"{prefix}-self-training"
    diff = versus(runs, a, b, metric, **kwargs)
    name = COLUMNS.get(metric, metric.replace("_", " "))
    arms = ("DOSPCoT", "self-training")
    if labels:
        held = [labels_cell([r for r in runs if r.trial.config == preset]) for preset in (a, b)]
        arms = (f"DOSPCoT ({held[0]} labels a run)", f"self-training ({held[1]})")
    return Glance(f"{name}, {arms[0]} minus {arms[1]}, paired by {paired_by}: {diff}", verdict(diff))


def with_headline(
    tables: Callable[[list[TrialRun]], list[str]], glance: Callable[[list[TrialRun]], Glance]
) -> Callable[[list[TrialRun]], list[str]]:
    """``tables`` followed by a line that states the study's headline comparison and its verdict as
    ``glance`` gives them to the results at a glance: the page that row links to then states them."""

    def tables_and_headline(runs: list[TrialRun]) -> list[str]:
        headline = glance(runs)
        return [
            *tables(runs),
            "",
            "Headline, as the [results at a glance](docs/results/index.md) give it: "
            f"{headline.headline}; {headline.verdict}.",
        ]

    return tables_and_headline


def run_cpu(run: TrialRun) -> str | None:
    """The CPU model and torch kernels that trained ``run`` (``run_info.json``'s ``cpu``; None where it
    did not record them)."""
    path = run.run_dir / "run_info.json"
    return json.loads(path.read_text()).get("cpu") if path.is_file() else None


def cpu_pairs(a: dict[int, TrialRun], b: dict[int, TrialRun]) -> tuple[list[int], list[int]]:
    """Of the seeds both ``a`` and ``b`` ran, those whose two runs trained on one CPU model and those
    on two (a run that did not record its CPU is in neither). Two models round differently even with
    one instruction set, so a pair from two holds that noise in its difference."""
    common = sorted(a.keys() & b.keys())
    cpus = {s: (run_cpu(a[s]), run_cpu(b[s])) for s in common}
    known = [s for s in common if None not in cpus[s]]
    return [s for s in known if cpus[s][0] == cpus[s][1]], [s for s in known if cpus[s][0] != cpus[s][1]]
