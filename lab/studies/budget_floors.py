"""The seventh label-budget exploration (issue 58), ``budget-explore-floors``: a floor of each round's
chosen queries for every reward class the views predict. In the sixth, DOSPCoT's MiniGrid settings
(half the queries on episode ends, half by the views' disagreement, on the decaying schedule) failed
on grid16, where episode ends are the goal's and the lava's and the step-cost class went short; floors
ask about the rarest predicted class first, whatever its episode ends. Its tables are
:mod:`~dospcot.lab.studies.budget`'s; every arm without floors and the oracles are the earlier
explorations' runs, reused."""

from __future__ import annotations

from dataclasses import replace

from dospcot.lab.report import TrialRun
from dospcot.lab.studies.budget import (
    FLOOR,
    OUTCOMES,
    RANDOM_SHARE,
    ROUNDS_ARM,
    exploration_tables,
    figure,
    spend,
)
from dospcot.lab.studies.budget_explore import (
    DECAY,
    DECAY_SWEEPS,
    GRID_LABELS,
    GRID_LAYOUT,
    HIGHWAY_LABELS,
    MINIGRID,
    OTHER_SWEEPS,
    OTHER_TASKS,
    arm_sweep,
    glance_of,
    minigrid_sweep,
)
from dospcot.lab.studies.declaration import Study, Sweep

FLOORS = {FLOOR: ("0.5",)}
"""Half of a round's chosen queries spread over the reward classes the views predict, from round 2, the
rarest class and its least certain samples first (``training.query_class_floor``)."""
GRID_DISAGREEMENT = {**GRID_LAYOUT, **spend("disagreement", "decay", GRID_LABELS)}
"""grid16's 20 labels by the views' disagreement alone, on the decaying schedule (round 1 at random)."""


def _five(sweep: Sweep) -> Sweep:
    """``sweep`` on seeds 0-4, as grid16's and the fast highway's arms run in a study of 10 seeds."""
    return replace(sweep, seeds=5)


def _floored(sweep: Sweep, task: str, preset: str) -> Sweep:
    """``sweep``'s arm with class floors: sweep ``budget-<task>-<its name>-floors`` of ``preset``."""
    return arm_sweep(
        task, f"{sweep.name.removeprefix(f'budget-{task}-')}-floors", preset, {**sweep.grid, **FLOORS}
    )


GRID_OUTCOMES, HIGHWAY_OUTCOMES = OTHER_SWEEPS[1], OTHER_SWEEPS[5]
DOORKEY_OUTCOMES, LAVAGAP_OUTCOMES = DECAY_SWEEPS[7], DECAY_SWEEPS[3]
DISAGREEMENT = spend("disagreement", "decay")
"""DOSPCoT's 100 labels by the views' disagreement alone, on the decaying schedule: round 1, before any
classifier, draws at random."""
FLOOR_SWEEPS = (
    OTHER_SWEEPS[0],
    _five(GRID_OUTCOMES),
    _five(_floored(GRID_OUTCOMES, "grid16", "grid16-dospcot")),
    _five(
        arm_sweep("grid16", "disagreement-decay-floors", "grid16-dospcot", {**GRID_DISAGREEMENT, **FLOORS})
    ),
    _five(arm_sweep("grid16", "disagreement-decay", "grid16-dospcot", GRID_DISAGREEMENT)),
    _five(
        arm_sweep(
            "grid16",
            "outcomes-decay-random-half",
            "grid16-dospcot",
            {**GRID_OUTCOMES.grid, RANDOM_SHARE: ("0.5",)},
        )
    ),
    DECAY_SWEEPS[4],
    DOORKEY_OUTCOMES,
    minigrid_sweep("doorkey", "disagreement-decay", "dospcot", DISAGREEMENT),
    DECAY_SWEEPS[0],
    LAVAGAP_OUTCOMES,
    minigrid_sweep("lavagap", "disagreement-decay", "dospcot", DISAGREEMENT),
    OTHER_SWEEPS[4],
    _five(HIGHWAY_OUTCOMES),
    _five(_floored(HIGHWAY_OUTCOMES, "fasthighway", "fasthighway-dospcot")),
    minigrid_sweep("doorkey", "outcomes-decay-floors", "dospcot", {**spend(OUTCOMES, "decay"), **FLOORS}),
    minigrid_sweep("lavagap", "outcomes-decay-floors", "dospcot", {**spend(OUTCOMES, "decay"), **FLOORS}),
)
"""Class floors beside the sixth exploration's DOSPCoT arm on grid16's layout 11 and the fast highway
(seeds 0-4) and the fifth's on both MiniGrid tasks (seeds 0-9); on grid16, disagreement alone with
and without floors, and half of each round's queries at random; on both MiniGrid tasks, disagreement
alone; with each task's oracle (seeds 0-9). Grid16's arms run first: they decide which others are
worth their cost."""
FLOORED = f"dospcot outcomes+disagreement decay class floors 50% {ROUNDS_ARM}"
ALONE = f"dospcot disagreement decay {ROUNDS_ARM}"
FLOOR_DESCRIPTIVE = (
    (FLOORED, DECAY, "class floors against none"),
    (ALONE, DECAY, "disagreement alone against half the queries on episode ends"),
    (
        f"dospcot disagreement decay class floors 50% {ROUNDS_ARM}",
        ALONE,
        "disagreement alone, with floors against without",
    ),
    (
        f"dospcot outcomes+disagreement decay 50% at random {ROUNDS_ARM}",
        DECAY,
        "half of each round's queries at random against a fifth",
    ),
)
TASKS = {**OTHER_TASKS, **MINIGRID}


def _tables(runs: list[TrialRun]) -> list[str]:
    seeds = "grid16 and the fast highway seeds 0-4, MiniGrid seeds 0-9 (the oracles' 0-9), each agent"
    return exploration_tables(
        TASKS,
        "budget-explore-floors",
        f"{seeds} drawing from its own generators, numerics 2",
        FLOOR_DESCRIPTIVE,
    )(runs)


STUDIES: dict[str, Study] = {
    "budget-explore-floors": Study(
        FLOOR_SWEEPS,
        _tables,
        "Labels that pay: the seventh exploration, class floors and disagreement alone",
        f"grid16 layout 11 at {GRID_LABELS} labels, both MiniGrid tasks at 100, the fast highway at "
        f"{HIGHWAY_LABELS} (exploratory)",
        glance_of(FLOOR_DESCRIPTIVE[0], "grid16 success, 20 labels, class floors minus none", "grid16-"),
        seeds=10,
        figure=figure(TASKS),
    )
}
