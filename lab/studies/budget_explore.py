"""The label-budget explorations, declared: ``budget-explore`` (MiniGrid, seeds 0-2, the
first), ``budget-explore-doorkey`` (DoorKey's most promising arms on seeds 0-9, each agent drawing
from its own generators, numerics 2) and ``budget-explore-admit`` (admitting all of U in round 1, on
DoorKey, a grid16 layout no study used and the fast highway) and ``budget-explore-peers`` (the arms
the hypotheses compare, at 100 labels on both MiniGrid tasks), ``budget-explore-decay`` (a decaying
schedule on both) and ``budget-explore-grid-highway`` (those settings on grid16 and the fast
highway); the seventh is :mod:`~dospcot_lab.studies.budget_classes`'s. Their tables are
:mod:`~dospcot_lab.studies.budget`'s."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.budget import (
    OUTCOMES,
    OWN,
    ROUNDS,
    budget_sweep,
    exploration,
    paired_difference,
    spend,
)
from dospcot_lab.studies.budget_arms import ADMIT, BUDGET, EXPLORATION, ROUNDS_ARM, SCHEDULE, STRATEGY, by_arm
from dospcot_lab.studies.declaration import EXPLORATORY, Glance, Study, Sweep
from dospcot_lab.studies.grid_studies import LAYOUT
from dospcot_lab.studies.tables import FRACTION

DESCRIPTIVE = (
    ("dospcot uniform " + ROUNDS_ARM, "dospcot uniform", "exploration by rounds against the pace, 10% mask"),
    (
        f"dospcot disagreement even {ROUNDS_ARM}",
        f"dospcot disagreement asap {ROUNDS_ARM}",
        "the budget spread evenly against spent at once",
    ),
    (
        f"dospcot outcomes+disagreement even {ROUNDS_ARM}",
        f"dospcot disagreement even {ROUNDS_ARM}",
        "half the queries on episode ends under the even schedule",
    ),
    (
        f"dospcot disagreement even {ROUNDS_ARM}",
        f"self-training uncertainty even {ROUNDS_ARM}",
        "the second view's disagreement against one view's uncertainty",
    ),
    (
        f"dospcot disagreement even {ROUNDS_ARM}",
        f"reward-model disagreement even {ROUNDS_ARM}",
        "co-training against the reward-model peer",
    ),
)
"""Comparisons the exploration reads (arm a, arm b, what a minus b asks), success paired by seed over
the seeds both ran, with no threshold and no verdict."""


def glance_of(
    comparison: tuple[str, str, str], headline: str, task: str = ""
) -> Callable[[list[TrialRun]], Glance]:
    """A study's row at a glance: ``headline``, then success of ``comparison``'s arm a minus arm b,
    paired by seed, over the runs of the presets starting ``task``."""

    def glance(runs: list[TrialRun]) -> Glance:
        arms = by_arm([r for r in runs if r.trial.config.startswith(task)])
        a, b, _ = comparison
        if a not in arms or b not in arms:
            return Glance("not rendered yet", EXPLORATORY)
        return Glance(f"{headline}, paired: {paired_difference(arms[a], arms[b])}", EXPLORATORY)

    return glance


def _of(prefix: str) -> Callable[[TrialRun], bool]:
    return lambda run: run.trial.config.startswith(prefix)


EXPLORE_SWEEPS = (
    # The control first: with every reward labelled, co-training has nothing to learn, so whatever
    # it loses against the oracle is the machinery's.
    Sweep(
        "budget-explore-lavagap-control",
        ("minigrid-lavagap-dospcot",),
        {FRACTION: ("1.0",), EXPLORATION: ("rounds", "pace")},
    ),
    # One agent of the oracle's view with every reward labelled: the run differs from the oracle's only
    # in the co-training machinery (the reward table, the keyed labels, the co-trainer's empty U).
    Sweep(
        "budget-explore-lavagap-control-single",
        ("minigrid-lavagap-self-training",),
        {FRACTION: ("1.0",), EXPLORATION: ("rounds",)},
    ),
    Sweep("queries-lavagap-oracle", ("minigrid-lavagap-oracle",), {}),
    Sweep(
        "queries-lavagap-dospcot",
        ("minigrid-lavagap-dospcot",),
        {FRACTION: ("0.1",), STRATEGY: ("uniform", "random", "uncertainty")},
    ),
    Sweep("budget-explore-lavagap-uniform", ("minigrid-lavagap-dospcot",), {FRACTION: ("0.1",), **ROUNDS}),
    Sweep("queries-doorkey-oracle", ("minigrid-doorkey-oracle",), {}),
    # The active-queries study's DOSPCoT arms at a 10% mask explore by the pace (seeds 0-9).
    Sweep(
        "queries-doorkey-dospcot",
        ("minigrid-doorkey-dospcot",),
        {FRACTION: ("0.1",), STRATEGY: ("uniform", "random", "uncertainty")},
    ),
    Sweep("budget-explore-doorkey-uniform", ("minigrid-doorkey-dospcot",), {FRACTION: ("0.1",), **ROUNDS}),
    Sweep(
        "budget-explore-doorkey-dospcot",
        ("minigrid-doorkey-dospcot",),
        {BUDGET: ("100",), STRATEGY: ("disagreement",), SCHEDULE: ("asap", "even"), **ROUNDS},
    ),
    Sweep(
        "budget-explore-doorkey-outcomes",
        ("minigrid-doorkey-dospcot",),
        {BUDGET: ("100",), STRATEGY: ('"outcomes+disagreement"',), SCHEDULE: ("even",), **ROUNDS},
    ),
    Sweep(
        "budget-explore-doorkey-self-training",
        ("minigrid-doorkey-self-training",),
        {BUDGET: ("100",), STRATEGY: ("uncertainty",), SCHEDULE: ("even",), **ROUNDS},
    ),
    Sweep(
        "budget-explore-doorkey-reward-model",
        ("minigrid-doorkey-reward-model",),
        {BUDGET: ("100",), STRATEGY: ("disagreement",), SCHEDULE: ("even",), **ROUNDS},
    ),
)


def arm_sweep(task: str, name: str, preset: str, grid: dict[str, tuple[str, ...]]) -> Sweep:
    """Sweep ``budget-<task>-<name>`` of preset ``preset`` (:func:`budget_sweep`)."""
    return budget_sweep(f"budget-{task}-{name}", preset, grid)


def minigrid_sweep(task: str, name: str, preset: str, grid: dict[str, tuple[str, ...]]) -> Sweep:
    """An arm (:func:`arm_sweep`) of MiniGrid ``task`` (``doorkey`` or ``lavagap``) and method ``preset``."""
    return arm_sweep(task, name, f"minigrid-{task}-{preset}", grid)


DOORKEY_SWEEPS = (
    Sweep("budget-doorkey-oracle", ("minigrid-doorkey-oracle",), OWN, numerics=2),
    minigrid_sweep("doorkey", "outcomes-even", "dospcot", spend(OUTCOMES)),
    minigrid_sweep("doorkey", "reward-model", "reward-model", spend("disagreement")),
    minigrid_sweep("doorkey", "outcomes-asap", "dospcot", spend(OUTCOMES, "asap")),
    minigrid_sweep("doorkey", "uniform", "dospcot", {FRACTION: ("0.1",)}),
)
"""The second exploration: DoorKey's most promising arms of the first, on seeds 0-9, each agent drawing
from its own generators, under numerics 2 (the oracle too, so that no comparison mixes versions)."""
DOORKEY_DESCRIPTIVE = (
    (
        f"dospcot outcomes+disagreement even {ROUNDS_ARM}",
        f"dospcot outcomes+disagreement asap {ROUNDS_ARM}",
        "the budget spread evenly against spent at once",
    ),
    (
        f"dospcot outcomes+disagreement even {ROUNDS_ARM}",
        f"reward-model disagreement even {ROUNDS_ARM}",
        "co-training against the reward-model peer",
    ),
    (
        f"dospcot outcomes+disagreement even {ROUNDS_ARM}",
        f"dospcot uniform {ROUNDS_ARM}",
        "100 chosen labels spread evenly against a blind 10% mask",
    ),
)

ALL_OF_U = {ADMIT: ("1.0",)}
"""Every unlabelled sample admitted in round 1 (``add_fraction_start`` 1.0, against the presets' 0.5,
the fast highway's 0.2): in the second exploration every labelled arm's pseudo-rewards were right,
yet half of U weighed 0 through round 2, and a sample of weight 0 in a replay window stops its
update, so the reward did not reach the start of the episode until round 3."""
GRID_LAYOUT = {LAYOUT: ("11",)}
"""A grid16 layout no study had used (the grid16-layouts study's are 101, 202 and 303)."""
ADMIT_SWEEPS = (
    *DOORKEY_SWEEPS[:2],
    DOORKEY_SWEEPS[4],
    minigrid_sweep("doorkey", "outcomes-even-all", "dospcot", {**spend(OUTCOMES), **ALL_OF_U}),
    minigrid_sweep("doorkey", "uniform-all", "dospcot", {FRACTION: ("0.1",), **ALL_OF_U}),
    # Where pseudo-rewards are not all right, admitting everything at once may cost what pacing saves.
    Sweep("budget-grid16-oracle", ("grid16-oracle",), {**GRID_LAYOUT, **OWN}, numerics=2),
    Sweep(
        "budget-grid16-uniform",
        ("grid16-dospcot",),
        {**GRID_LAYOUT, ADMIT: ("0.5", "1.0"), **ROUNDS, **OWN},
        numerics=2,
    ),
    # The fast highway's five reward classes are harder to tell apart than DoorKey's two; its preset
    # admits a fifth of U in round 1.
    Sweep(
        "budget-fasthighway-uniform",
        ("fasthighway-dospcot",),
        {ADMIT: ("0.2", "1.0"), **ROUNDS, **OWN},
        numerics=2,
    ),
    Sweep("budget-fasthighway-oracle", ("fasthighway-oracle",), OWN, numerics=2),
)
"""The third exploration: DoorKey's even and blind arms of the second admitting all of U in round 1
(beside the second's runs of them, reused), grid16's 5% mask on layout 11 admitting half or all, and
the fast highway's 10% mask admitting a fifth (its preset) or all."""
ALL_ARM = "admitting 100% of U in round 1"
ADMIT_DESCRIPTIVE = (
    (
        f"dospcot outcomes+disagreement even {ROUNDS_ARM} {ALL_ARM}",
        f"dospcot outcomes+disagreement even {ROUNDS_ARM}",
        "100 chosen labels, admitting all of U in round 1 against half",
    ),
    (
        f"dospcot uniform {ROUNDS_ARM} {ALL_ARM}",
        f"dospcot uniform {ROUNDS_ARM}",
        "a blind 10% mask, admitting all of U in round 1 against half",
    ),
    (
        f"dospcot uniform {ROUNDS_ARM} {ALL_ARM}",
        f"dospcot uniform {ROUNDS_ARM} admitting 50% of U in round 1",
        "grid16's 5% mask, admitting all of U in round 1 against half",
    ),
    (
        f"dospcot uniform {ROUNDS_ARM} {ALL_ARM}",
        f"dospcot uniform {ROUNDS_ARM} admitting 20% of U in round 1",
        "the fast highway's 10% mask, admitting all of U in round 1 against a fifth",
    ),
)


PEER_SWEEPS = (
    *DOORKEY_SWEEPS[:2],
    DOORKEY_SWEEPS[3],
    minigrid_sweep("doorkey", "random-even", "dospcot", spend("random")),
    minigrid_sweep("doorkey", "self-training", "self-training", spend("uncertainty")),
    minigrid_sweep("doorkey", "reward-model-outcomes", "reward-model", spend(OUTCOMES)),
    Sweep("budget-lavagap-oracle", ("minigrid-lavagap-oracle",), OWN, numerics=2),
    minigrid_sweep("lavagap", "outcomes-even", "dospcot", spend(OUTCOMES)),
    minigrid_sweep("lavagap", "outcomes-asap", "dospcot", spend(OUTCOMES, "asap")),
    minigrid_sweep("lavagap", "random-even", "dospcot", spend("random")),
    minigrid_sweep("lavagap", "self-training", "self-training", spend("uncertainty")),
    minigrid_sweep("lavagap", "reward-model-outcomes", "reward-model", spend(OUTCOMES)),
)
"""The fourth exploration: on both MiniGrid tasks at 100 labels, the arms the label-budget hypotheses
compare, each against DOSPCoT's half on episode ends and half by disagreement spread evenly: spent at
once (spreading), random queries on the same schedule (the blind control), self-training with
uncertainty and the reward-model peer given the same strategy (the second view). DoorKey's first
three are the second exploration's runs, reused; every preset admits half of U in round 1."""
EVEN = f"dospcot outcomes+disagreement even {ROUNDS_ARM}"
PEER_DESCRIPTIVE = (
    (
        EVEN,
        f"dospcot outcomes+disagreement asap {ROUNDS_ARM}",
        "the budget spread evenly against spent at once",
    ),
    (EVEN, f"dospcot random even {ROUNDS_ARM}", "the views' choice against random queries, same schedule"),
    (EVEN, f"self-training uncertainty even {ROUNDS_ARM}", "two views against one view's uncertainty"),
    (
        EVEN,
        f"reward-model outcomes+disagreement even {ROUNDS_ARM}",
        "co-training against the reward-model peer, same strategy",
    ),
)

DECAY_SWEEPS = (
    *PEER_SWEEPS[6:9],
    minigrid_sweep("lavagap", "outcomes-decay", "dospcot", spend(OUTCOMES, "decay")),
    *DOORKEY_SWEEPS[:2],
    DOORKEY_SWEEPS[3],
    minigrid_sweep("doorkey", "outcomes-decay", "dospcot", spend(OUTCOMES, "decay")),
)
"""The fifth exploration: DOSPCoT's 100 labels on a decaying schedule (round r's share in proportion to
1 / r, 44% in round 1 of 5) on both MiniGrid tasks, seeds 0-9, beside the fourth's oracle, even and
at-once arms, reused. In the fourth, LavaGap's even arm left the goal unlabelled through round 1 on
most seeds, and its agents rarely reached it."""
DECAY = f"dospcot outcomes+disagreement decay {ROUNDS_ARM}"
DECAY_DESCRIPTIVE = (
    (DECAY, EVEN, "a decaying schedule against an even one"),
    (
        DECAY,
        f"dospcot outcomes+disagreement asap {ROUNDS_ARM}",
        "a decaying schedule against spending at once",
    ),
)

GRID_LABELS = "20"
"""grid16's budget: about what a 2% mask revealed to one agent (17 labels) in the active-queries study."""
HIGHWAY_LABELS = "400"
"""The fast highway's: what a 2% mask revealed to one agent there (400)."""


def _peers(task: str, prefix: str, labels: str, grid: dict[str, tuple[str, ...]]) -> tuple[Sweep, ...]:
    """The arms the sixth exploration runs on a task (``prefix`` its presets' name) at ``labels``, each
    on the decaying schedule: DOSPCoT's MiniGrid strategy, self-training with uncertainty and the
    reward-model peer with disagreement."""
    return (
        arm_sweep(task, "outcomes-decay", f"{prefix}-dospcot", {**grid, **spend(OUTCOMES, "decay", labels)}),
        arm_sweep(
            task,
            "self-training-decay",
            f"{prefix}-self-training",
            {**grid, **spend("uncertainty", "decay", labels)},
        ),
        arm_sweep(
            task,
            "reward-model-decay",
            f"{prefix}-reward-model",
            {**grid, **spend("disagreement", "decay", labels)},
        ),
    )


OTHER_SWEEPS = (
    replace(ADMIT_SWEEPS[5], seeds=10),
    *_peers("grid16", "grid16", GRID_LABELS, GRID_LAYOUT),
    replace(ADMIT_SWEEPS[-1], seeds=10),
    *_peers("fasthighway", "fasthighway", HIGHWAY_LABELS, {}),
)
"""The sixth exploration: the MiniGrid settings (half the queries on episode ends, half by the views'
disagreement, on the decaying schedule) on grid16's layout 11 and the fast highway, at budgets about
what one agent's 2% mask revealed there, against the one-view peer and the reward-model peer of the
label-budget hypotheses on the same schedule, seeds 0-4; the oracles are the third exploration's
runs, reused."""
OTHER_DESCRIPTIVE = (
    (DECAY, f"self-training uncertainty decay {ROUNDS_ARM}", "two views against one view's uncertainty"),
    (DECAY, f"reward-model disagreement decay {ROUNDS_ARM}", "co-training against the reward-model peer"),
)

DOORKEY = {"MiniGrid-DoorKey-5x5-v0": _of("minigrid-doorkey-")}
MINIGRID = {"MiniGrid-LavaGapS7-v0": _of("minigrid-lavagap-"), **DOORKEY}
OTHER_TASKS = {"grid16, layout 11": _of("grid16-"), "fast highway": _of("fasthighway-")}
ADMIT_TASKS = {**DOORKEY, **OTHER_TASKS}
"""Each exploration's tasks: a table and a figure's panel each, of the runs whose preset starts so."""

TEN_SEEDS = "seeds 0-9, each agent drawing from its own generators, numerics 2"

STUDIES: dict[str, Study] = dict(
    (
        exploration(
            "budget-explore",
            EXPLORE_SWEEPS,
            MINIGRID,
            "seeds 0-2 (the oracle rows reuse the active-queries study's seeds 0-9)",
            DESCRIPTIVE,
            "Labels that pay: exploring label budgets, schedules and the reward-model peer",
            "MiniGrid LavaGapS7 and DoorKey-5x5 (exploratory)",
            # The first exploration's clearest lever: on DoorKey at a 10% mask, exploring by rounds or
            # the pace.
            glance_of(
                DESCRIPTIVE[0],
                "DoorKey success, 10% mask, exploring by rounds minus by the pace",
                "minigrid-doorkey-",
            ),
            seeds=3,
        ),
        exploration(
            "budget-explore-doorkey",
            DOORKEY_SWEEPS,
            DOORKEY,
            TEN_SEEDS,
            DOORKEY_DESCRIPTIVE,
            "Labels that pay: the second exploration, DoorKey on ten seeds",
            "MiniGrid DoorKey-5x5 (exploratory)",
            glance_of(DOORKEY_DESCRIPTIVE[0], "success, 100 labels spread evenly minus spent at once"),
        ),
        exploration(
            "budget-explore-admit",
            ADMIT_SWEEPS,
            ADMIT_TASKS,
            TEN_SEEDS,
            ADMIT_DESCRIPTIVE,
            "Labels that pay: the third exploration, admitting all of U in round 1",
            "MiniGrid DoorKey-5x5, grid16 layout 11 and the fast highway (exploratory)",
            glance_of(
                ADMIT_DESCRIPTIVE[0],
                "DoorKey success, 100 labels, admitting all of U minus half",
                "minigrid-",
            ),
        ),
        exploration(
            "budget-explore-peers",
            PEER_SWEEPS,
            MINIGRID,
            TEN_SEEDS,
            PEER_DESCRIPTIVE,
            "Labels that pay: the fourth exploration, the peers on both MiniGrid tasks",
            "MiniGrid LavaGapS7 and DoorKey-5x5 at 100 labels (exploratory)",
            glance_of(
                PEER_DESCRIPTIVE[3],
                "LavaGap success, 100 labels, DOSPCoT minus the reward-model peer",
                "minigrid-lavagap-",
            ),
        ),
        exploration(
            "budget-explore-decay",
            DECAY_SWEEPS,
            MINIGRID,
            TEN_SEEDS,
            DECAY_DESCRIPTIVE,
            "Labels that pay: the fifth exploration, a decaying schedule on both MiniGrid tasks",
            "MiniGrid LavaGapS7 and DoorKey-5x5 at 100 labels (exploratory)",
            glance_of(
                DECAY_DESCRIPTIVE[0], "LavaGap success, 100 labels, decaying minus even", "minigrid-lavagap-"
            ),
        ),
        exploration(
            "budget-explore-grid-highway",
            OTHER_SWEEPS,
            OTHER_TASKS,
            "seeds 0-4 (the oracles' 0-9), each agent drawing from its own generators, numerics 2",
            OTHER_DESCRIPTIVE,
            "Labels that pay: the sixth exploration, the MiniGrid settings on grid16 and the fast highway",
            f"grid16 layout 11 at {GRID_LABELS} labels, the fast highway at {HIGHWAY_LABELS} (exploratory)",
            glance_of(
                OTHER_DESCRIPTIVE[1],
                "fast highway success, DOSPCoT minus the reward-model peer",
                "fasthighway-",
            ),
            seeds=5,
        ),
    )
)
