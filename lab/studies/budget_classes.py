"""The label-budget explorations of reward classes that go missing, declared. In the sixth,
DOSPCoT's MiniGrid settings (half the queries on episode ends, half by the views' disagreement, on
the decaying schedule) reached grid16's goal on none of five seeds.

- ``budget-explore-floors`` (the seventh) asks whether the queries were at fault: a floor of each
  round's chosen queries for every reward class the views predict, disagreement alone (round 1 at
  random), and half of each round's queries at random, on grid16 (and floors on the fast highway).
- ``budget-explore-refit`` (the eighth) tries what the seventh's runs showed instead: a class first
  labelled after round 1 had an output no fit had trained, so the consensus gave it to no sample, or
  to almost all. ``cotraining.refit_new_classes`` has each classifier learn the labels alone again
  when a class first shows.
- ``budget-explore-ends`` (the ninth) tries what the eighth's grid16 runs showed: with half the
  queries on episode ends the goal is a tenth of the labels, and its reward spread to ordinary steps.
  ``env.episode_end_classes`` gives a class labelled only on keys that ended their episode to such
  keys alone, as the MiniGrid presets' ``[gym]`` key of that name does; and it runs the refit on
  LavaGap and the fast highway.

Their tables are :mod:`~dospcot_lab.studies.budget`'s; every arm without the new setting and the
oracles are the earlier explorations' runs, reused."""

from __future__ import annotations

from dataclasses import replace

from dospcot_lab.studies.budget import ENDS_ON, REFIT_ON, exploration, spend
from dospcot_lab.studies.budget_arms import FLOOR, QUOTA, RANDOM_SHARE, REFIT_ARM, ROUNDS_ARM, goal_on_ends
from dospcot_lab.studies.budget_explore import (
    DECAY,
    DECAY_SWEEPS,
    DOORKEY,
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
from dospcot_lab.studies.declaration import Study, Sweep

FLOORS = {FLOOR: ("0.5",)}
"""Half of a round's chosen queries spread over the reward classes the views predict, from round 2, the
rarest class and its least certain samples first (``training.query_class_floor``)."""
GRID_DISAGREEMENT = {**GRID_LAYOUT, **spend("disagreement", "decay", GRID_LABELS)}
"""grid16's 20 labels by the views' disagreement alone, on the decaying schedule (round 1 at random)."""


def _five(sweep: Sweep) -> Sweep:
    """``sweep`` on seeds 0-4, as grid16's and the fast highway's arms run in a study of 10 seeds."""
    return replace(sweep, seeds=5)


def _with(sweep: Sweep, suffix: str, settings: dict[str, tuple[str, ...]]) -> Sweep:
    """``sweep``'s arm with ``settings`` added to its grid: sweep ``<its name>-<suffix>``, of its preset
    and seeds."""
    return replace(sweep, name=f"{sweep.name}-{suffix}", grid={**sweep.grid, **settings})


GRID_OUTCOMES, HIGHWAY_OUTCOMES = OTHER_SWEEPS[1], OTHER_SWEEPS[5]
DOORKEY_OUTCOMES = DECAY_SWEEPS[7]
FLOOR_SWEEPS = (
    OTHER_SWEEPS[0],
    _five(GRID_OUTCOMES),
    _five(_with(GRID_OUTCOMES, "floors", FLOORS)),
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
    OTHER_SWEEPS[4],
    _five(HIGHWAY_OUTCOMES),
    _five(_with(HIGHWAY_OUTCOMES, "floors", FLOORS)),
)
"""The seventh exploration: class floors beside the sixth exploration's DOSPCoT arm on grid16's layout
11 and the fast highway, and on grid16 disagreement alone with and without floors and half of each
round's queries at random (seeds 0-4), with each task's oracle (seeds 0-9). Its MiniGrid arms were
stopped after the grid's runs showed the queries were not at fault (the eighth exploration)."""
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
REFIT_TASKS = {"grid16, layout 11": OTHER_TASKS["grid16, layout 11"], **DOORKEY}


GRID_REFIT = _with(_five(GRID_OUTCOMES), "refit", REFIT_ON)

REFIT_SWEEPS = (
    OTHER_SWEEPS[0],
    _five(GRID_OUTCOMES),
    GRID_REFIT,
    _five(OTHER_SWEEPS[2]),
    _with(_five(OTHER_SWEEPS[2]), "refit", REFIT_ON),
    FLOOR_SWEEPS[4],
    _with(FLOOR_SWEEPS[4], "refit", REFIT_ON),
    _five(OTHER_SWEEPS[3]),
    _with(GRID_REFIT, "candidates", {QUOTA: ('"candidates"',)}),
    DECAY_SWEEPS[4],
    DOORKEY_OUTCOMES,
    _with(DOORKEY_OUTCOMES, "refit", REFIT_ON),
    minigrid_sweep(
        "doorkey", "disagreement-decay-refit", "dospcot", {**spend("disagreement", "decay"), **REFIT_ON}
    ),
)
"""The eighth exploration, on grid16's layout 11 (seeds 0-4) and DoorKey (seeds 0-9), each arm with the
refit beside its runs without it where they exist: DOSPCoT's MiniGrid settings (the fifth's and
sixth's arm) and disagreement alone (the seventh's; on DoorKey it has no run without the refit); on
grid16 the one-view peer, whose one classifier shares the fault, beside the sixth's reward-model peer,
which the fault does not touch (it fits on the labels alone), and the MiniGrid settings with each class
admitting the same share of its own candidates (``cotraining.quota = "candidates"``): half the
queries on episode ends make the goal a tenth of grid16's labels, and SPaMCo's quota then admits a
tenth of the pool as the goal, where two samples are. The oracles are the earlier explorations'
runs (seeds 0-9). LavaGap and the fast highway with the refit are not run yet."""
REFITTED = f"dospcot outcomes+disagreement decay {REFIT_ARM} {ROUNDS_ARM}"
ALONE_REFITTED = f"dospcot disagreement decay {REFIT_ARM} {ROUNDS_ARM}"
SELF_REFITTED = f"self-training uncertainty decay {REFIT_ARM} {ROUNDS_ARM}"
REFIT_DESCRIPTIVE = (
    (REFITTED, DECAY, "refitting on a new class against not"),
    (
        SELF_REFITTED,
        f"self-training uncertainty decay {ROUNDS_ARM}",
        "the one-view peer refitting on a new class against not",
    ),
    (
        REFITTED,
        SELF_REFITTED,
        "two views against one view's uncertainty, both refitting",
    ),
    (
        ALONE_REFITTED,
        ALONE,
        "disagreement alone, refitting on a new class against not",
    ),
    (
        ALONE_REFITTED,
        REFITTED,
        "disagreement alone against half the queries on episode ends, both refitting",
    ),
    (
        ALONE_REFITTED,
        SELF_REFITTED,
        "disagreement alone against one view's uncertainty, both refitting",
    ),
    (
        ALONE_REFITTED,
        f"reward-model disagreement decay {ROUNDS_ARM}",
        "disagreement alone, refitting, against the reward-model peer",
    ),
    (
        f"dospcot outcomes+disagreement decay {REFIT_ARM} quota candidates {ROUNDS_ARM}",
        REFITTED,
        "each class admitting a share of its own candidates against SPaMCo's quota, both refitting",
    ),
)
REFIT_SEEDS = (
    "grid16 seeds 0-4, DoorKey seeds 0-9 (the oracles' 0-9), each agent drawing from its own generators, "
    "numerics 2"
)
FIVE_SEEDS = "seeds 0-4 (the oracles' 0-9), each agent drawing from its own generators, numerics 2"


def _ends(sweep: Sweep) -> Sweep:
    """``sweep``'s grid16 arm with the goal kept to episode ends, on seeds 0-9."""
    return replace(_with(sweep, "ends", ENDS_ON), seeds=10)


LAVAGAP_DECAY = DECAY_SWEEPS[3]
ENDS_SWEEPS = (
    OTHER_SWEEPS[0],
    GRID_REFIT,
    _ends(GRID_REFIT),
    REFIT_SWEEPS[6],
    _ends(REFIT_SWEEPS[6]),
    REFIT_SWEEPS[4],
    _ends(REFIT_SWEEPS[4]),
    REFIT_SWEEPS[7],
    _ends(REFIT_SWEEPS[7]),
    DECAY_SWEEPS[0],
    LAVAGAP_DECAY,
    _with(LAVAGAP_DECAY, "refit", REFIT_ON),
    OTHER_SWEEPS[4],
    FLOOR_SWEEPS[7],
    _with(FLOOR_SWEEPS[7], "refit", REFIT_ON),
)
"""The ninth exploration: on grid16's layout 11 (seeds 0-9) the eighth's refitting arms (DOSPCoT's
MiniGrid settings, disagreement alone, the one-view peer) and the sixth's reward-model peer, each
with the goal kept to episode ends, beside their runs without it (seeds 0-4); the refit on LavaGap
(seeds 0-9) and the fast highway (seeds 0-4) with the MiniGrid settings, beside their runs without
it. The oracles are the earlier explorations' runs (seeds 0-9)."""
ENDS_TASKS = {"grid16, layout 11": OTHER_TASKS["grid16, layout 11"], **MINIGRID, **OTHER_TASKS}
ENDED = goal_on_ends(REFITTED)
ENDS_DESCRIPTIVE = (
    (ENDED, REFITTED, "the goal kept to episode ends against not, both refitting"),
    (
        goal_on_ends(ALONE_REFITTED),
        ALONE_REFITTED,
        "disagreement alone, the goal kept to episode ends against not",
    ),
    (
        ENDED,
        goal_on_ends(SELF_REFITTED),
        "two views against one view's uncertainty, with the refit and the goal on episode ends",
    ),
    (
        ENDED,
        goal_on_ends(f"reward-model disagreement decay {ROUNDS_ARM}"),
        "co-training against the reward-model peer, the goal on episode ends",
    ),
    (REFITTED, DECAY, "refitting on a new class against not"),
)
ENDS_SEEDS = (
    "grid16 seeds 0-9 with the goal on episode ends (0-4 without), LavaGap seeds 0-9, the fast highway "
    "seeds 0-4 (the oracles' 0-9), each agent drawing from its own generators, numerics 2"
)


STUDIES: dict[str, Study] = dict(
    (
        exploration(
            "budget-explore-floors",
            FLOOR_SWEEPS,
            OTHER_TASKS,
            FIVE_SEEDS,
            FLOOR_DESCRIPTIVE,
            "Labels that pay: the seventh exploration, class floors and disagreement alone",
            f"grid16 layout 11 at {GRID_LABELS} labels, the fast highway at {HIGHWAY_LABELS} (exploratory)",
            glance_of(FLOOR_DESCRIPTIVE[0], "grid16 success, 20 labels, class floors minus none", "grid16-"),
        ),
        exploration(
            "budget-explore-refit",
            REFIT_SWEEPS,
            REFIT_TASKS,
            REFIT_SEEDS,
            REFIT_DESCRIPTIVE,
            "Labels that pay: the eighth exploration, refitting the classifiers on a new class",
            f"grid16 layout 11 at {GRID_LABELS} labels, DoorKey-5x5 at 100 (exploratory)",
            glance_of(
                REFIT_DESCRIPTIVE[0],
                "grid16 success, 20 labels, refitting on a new class minus not",
                "grid16-",
            ),
        ),
        exploration(
            "budget-explore-ends",
            ENDS_SWEEPS,
            ENDS_TASKS,
            ENDS_SEEDS,
            ENDS_DESCRIPTIVE,
            "Labels that pay: the ninth exploration, the goal kept to episode ends",
            f"grid16 layout 11 at {GRID_LABELS} labels, LavaGapS7 at 100, the fast highway at "
            f"{HIGHWAY_LABELS} (exploratory)",
            glance_of(
                ENDS_DESCRIPTIVE[0],
                "grid16 success, 20 labels, the goal on episode ends minus not",
                "grid16-",
            ),
        ),
    )
)
