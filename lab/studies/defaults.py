"""The defaults study: version 2 of the defaults against version 1, paired by seed on
``grid16-dospcot`` and ``minigrid-doorkey-dospcot``, each config giving only its preset (so every
moved default takes its version's value). Version 2 replaces version 1 as the adopted version where,
on both presets, the lower end of the 95% interval of (version 2 minus version 1) lies above -0.05
for success and for pseudo-reward accuracy (non-inferiority; docs/guide/defaults.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.tables import (
    ADOPTION_METRICS,
    ADOPTION_SEEDS,
    CLASS_RECALL,
    CLASS_RECALL_NOTE,
    NON_INFERIOR_WORDS,
    adoption_glance,
    best_case,
    cpu_pairs,
    held_lines,
    non_inferior,
    paired,
    version_rows,
)

PRESETS = ("grid16-dospcot", "minigrid-doorkey-dospcot")
METRICS = tuple(ADOPTION_METRICS)
VERSIONS = (1, 2)


@dataclass(frozen=True)
class VersionPair:
    """A new version of the defaults against an old one on :data:`PRESETS`, paired by seed, decided by
    the adoption rule: a study's tables and its row of the results at a glance.

    :param old: the version adopted when the study was registered.
    :param new: the candidate.
    :param version_of: the version a run of the study's sweeps stands for (None: a run it does not read).
    """

    old: int
    new: int
    version_of: Callable[[TrialRun], int | None]

    @classmethod
    def named_in_grid(cls, old: int, new: int) -> VersionPair:
        """The pair whose runs each name their version in their sweep's grid (``defaults``)."""

        def version_of(run: TrialRun) -> int | None:
            named = run.trial.params.get("defaults")
            return int(named) if named in (str(old), str(new)) else None

        return cls(old, new, version_of)

    def by_seed(self, runs: list[TrialRun], preset: str, version: int) -> dict[int, TrialRun]:
        """The runs of ``preset`` standing for ``version``, by seed."""
        return {r.trial.seed: r for r in runs if r.trial.config == preset and self.version_of(r) == version}

    def differences(self, runs: list[TrialRun], preset: str) -> dict[str, SeedSummary]:
        """Per metric: the new version minus the old, paired by seed."""
        new, old = self.by_seed(runs, preset, self.new), self.by_seed(runs, preset, self.old)
        return {metric: paired(new, old, metric) for metric in METRICS}

    def tables(self, runs: list[TrialRun]) -> list[str]:
        """Per preset and version: success, pseudo-reward accuracy, labels and CPU time per run; then
        each difference, new minus old, against the non-inferiority margin."""
        rows = version_rows(
            lambda preset, version: list(self.by_seed(runs, preset, version).values()),
            PRESETS,
            (self.old, self.new),
            "defaults",
            {**ADOPTION_METRICS, **CLASS_RECALL, "labelled_steps": "labels"},
        )
        differences = self.by_preset(runs)
        early = []
        for preset, best in self.decided_early(runs, differences).items():
            n = differences[preset]["success"].n
            cells = ", ".join(f"{m} {d}" for m, d in best.items())
            early.append(
                f"- `{preset}` holds {n} of its {ADOPTION_SEEDS} pairs, and the rule fails whatever the "
                f"other {ADOPTION_SEEDS - n} show: with each at the most it could read (success and "
                f"pseudo-reward accuracy 1), the differences would read {cells}."
            )
        return [
            "",
            *rows,
            "",
            CLASS_RECALL_NOTE,
            "",
            f"Version {self.new} minus version {self.old}, paired by seed:",
            "",
            *held_lines(differences, non_inferior, NON_INFERIOR_WORDS),
            *(["", *early] if early else []),
            *self.cpu_lines(runs),
        ]

    def cpu_lines(self, runs: list[TrialRun]) -> list[str]:
        """How many of each preset's pairs trained on one CPU model (``run_info.json``'s ``cpu``), and
        how many of those took one course (:func:`_same_course`): a pair from two models holds their
        rounding's noise as well as the versions' difference, and a pair that took one course shows
        the versions' settings trained alike there."""
        cells = []
        for preset in PRESETS:
            new, old = self.by_seed(runs, preset, self.new), self.by_seed(runs, preset, self.old)
            seeds = new.keys() & old.keys()
            one_cpu = cpu_pairs(new, old)[0]
            alike = sum(_same_course(new[s], old[s]) for s in one_cpu)
            if seeds:
                cells.append(f"`{preset}` {len(one_cpu)} of {len(seeds)} (one course: {alike})")
        if not cells:
            return []
        return [
            "",
            f"Pairs trained on one CPU model (`run_info.json`'s `cpu`): {', '.join(cells)}. A pair from two "
            "models holds their rounding's noise as well as the versions' difference: it widens the "
            "interval and favours neither version. One course: a pair whose two runs read the same "
            "greedy return, success and pseudo-reward accuracy for each agent in every round.",
        ]

    def glance(self, runs: list[TrialRun]) -> Glance:
        """The headline: success, new minus old, on the preset that decides (a failing one first); the
        verdict: adopt the new version only where every difference on both presets is non-inferior."""
        differences = self.by_preset(runs)
        return adoption_glance(
            differences,
            f"defaults {self.new} minus {self.old}",
            (
                f"version {self.new} not shown non-inferior: not adopted",
                "not measured yet (a preset lacks one version's runs)",
                f"version {self.new} non-inferior: adopt it",
            ),
            list(self.decided_early(runs, differences)),
        )

    def by_preset(self, runs: list[TrialRun]) -> dict[str, dict[str, SeedSummary]]:
        """Per preset of :data:`PRESETS`: :meth:`differences`."""
        return {preset: self.differences(runs, preset) for preset in PRESETS}

    def best_cases(self, runs: list[TrialRun], preset: str) -> dict[str, SeedSummary]:
        """Per metric: the new version minus the old on ``preset`` with every seed the new one has not
        run yet at its best (:func:`~dospcot_lab.studies.tables.best_case`)."""
        new, old = self.by_seed(runs, preset, self.new), self.by_seed(runs, preset, self.old)
        return {metric: best_case(new, old, metric) for metric in METRICS}

    def decided_early(
        self, runs: list[TrialRun], differences: dict[str, dict[str, SeedSummary]]
    ) -> dict[str, dict[str, SeedSummary]]:
        """The presets that, short of their :data:`ADOPTION_SEEDS` pairs, fail the adoption rule whatever
        the pairs they lack show, each with its best case (:meth:`best_cases`), which fails it.

        :param differences: :meth:`by_preset` of ``runs``.
        """
        early = {}
        for preset in PRESETS:
            if not 0 < differences[preset]["success"].n < ADOPTION_SEEDS:
                continue  # a preset with every pair, or none, is read as it is
            best = self.best_cases(runs, preset)
            if best["success"].n and not all(map(non_inferior, best.values())):
                early[preset] = best
        return early


COURSE = ("round", "agent", "greedy_return", "success", "pseudo_accuracy")
"""The ``metrics.csv`` columns that make a run's course (:func:`_same_course`)."""


def _same_course(a: TrialRun, b: TrialRun) -> bool:
    """Whether two runs took one course: the same :data:`COURSE` figures for each agent in every round
    of their ``metrics.csv`` (NaN, where a figure is undefined, matching NaN)."""
    course_a, course_b = ([[row.get(c, np.nan) for c in COURSE] for row in r.curves] for r in (a, b))
    return np.array_equal(np.array(course_a, float), np.array(course_b, float), equal_nan=True)


TWO_AGAINST_ONE = VersionPair(1, 2, lambda run: int(run.trial.params.get("defaults", 1)))
"""The defaults study: each run names its version in its grid."""


VERSION_SWEEPS = {
    version: Sweep(f"defaults-{version}", PRESETS, {"defaults": (str(version),)}, batch_seeds=1)
    for version in VERSIONS
}
"""Each version's sweep: both presets, nothing but the version set, under numerics 1 (a sweep's own)."""


STUDIES: dict[str, Study] = {
    "defaults": Study(
        tuple(VERSION_SWEEPS.values()),
        TWO_AGAINST_ONE.tables,
        "Version 2 of the defaults against version 1",
        "grid16 (layout 0) and MiniGrid DoorKey-5x5",
        TWO_AGAINST_ONE.glance,
        seeds=ADOPTION_SEEDS,
        confirmatory=True,
    ),
}
