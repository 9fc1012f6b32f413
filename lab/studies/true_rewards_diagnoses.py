"""The true-rewards study's diagnoses: second controls that each change one part of the co-training path
where the control fell short of the oracle (:mod:`dospcot_lab.studies.true_rewards`)."""

from __future__ import annotations

import dataclasses

EXPLORATION = "training.exploration"


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """A second control that changes one part of the path, where the control fell short of the oracle.

    :param arm: its arm's name in the tables.
    :param what: what it changes, as the differences name it.
    :param suffix: its sweeps' names end ``-<suffix>``.
    :param params: the settings it adds to the control's.
    :param seeds: the tasks it trains on, each with its number of seeds.
    :param against: another diagnosis it differs from in one part alone, which it is also compared with.
    :param alone: that part, as the differences name it.
    """

    arm: str
    what: str
    suffix: str
    params: dict[str, str]
    seeds: dict[str, int]
    against: Diagnosis | None = None
    alone: str = ""


BY_ROUNDS = Diagnosis(
    "control, exploration by rounds",
    "exploration by rounds",
    "rounds",
    {EXPLORATION: "rounds"},
    {"lavagap": 5, "doorkey": 5},
)
"""Version 2's exploration: the pace reached 1 after LavaGap's first round, and the agents' epsilon its
floor with it, while the oracle's falls over the rounds. Added on LavaGap after its control's first
three seeds, on DoorKey after its ten."""
SHORT_ROUNDS = Diagnosis(
    "control, 20 short rounds",
    "exploration by rounds and 20 rounds of 2,500 steps",
    "short-rounds",
    {EXPLORATION: "rounds", "training.rounds": "20", "training.steps_per_round": "2500"},
    {"doorkey": 5, "lavagap": 5},
)
"""The same env steps in rounds a quarter as long: a step is rewarded in the agents' replay only once a
round's co-training has admitted it, so the oracle learns from a step as soon as it is taken and the
control a round later (in round 1, from the labelled share alone)."""
PASSES = Diagnosis(
    "control, 4 passes a round",
    "exploration by rounds and 4 co-training passes a round",
    "passes",
    {EXPLORATION: "rounds", "training.cotrain_passes": "4"},
    {"doorkey": 10, "lavagap": 10},
    against=BY_ROUNDS,
    alone="4 co-training passes a round",
)
"""Exploration by rounds, each round's co-training in four passes (``training.cotrain_passes``): the
lag cut as :data:`SHORT_ROUNDS` cuts it, while the rounds, their policy updates, the exploration schedule
and the evaluations stay :data:`BY_ROUNDS`'s, so against that diagnosis it measures the lag alone. Added
after every seed of the other two diagnoses had been read; LavaGap's seeds 5-9 were added after its
seeds 0-4 had been read, since the oracle's seeds 0-4 there are its five best (0.990 against 0.780), and
DoorKey's after its seeds 0-4 had matched the oracle, so that the arm decides on the control's ten."""
SCORE_PASSES = Diagnosis(
    "control, 10 score passes",
    "exploration by rounds and 10 score passes a round",
    "score-passes",
    {EXPLORATION: "rounds", "training.cotrain_passes": "10", "training.pass_kind": "score"},
    {"doorkey": 10, "lavagap": 10},
    against=BY_ROUNDS,
    alone="10 score passes a round",
)
"""Exploration by rounds, each round's collection in ten parts, each but the last followed by a score
pass (``training.pass_kind = "score"``): the classifiers as the last co-training left them admit the
steps taken since, with no fit, so the lag falls to a tenth of a round from round 2 at the cost of a
forward pass, where :data:`PASSES` refits every classifier at each pass. Round 1 keeps its whole lag:
no co-training precedes its passes. Added after every seed of the other diagnoses had been read, and
after two runs outside the record (the untuned study's DistShift1 control under version 10, with every
sample admitted from round 1) had reached that task's goal on neither seed by round 3, where the
oracle had on both: there the path's loss is not the admissions'."""
DIAGNOSES = (BY_ROUNDS, SHORT_ROUNDS, PASSES, SCORE_PASSES)
