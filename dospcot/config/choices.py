"""The named choices of a config, each spelled once: a ``Literal`` type for the fields and the
dataclass checks, and its values as a tuple for messages and for the code that branches on them."""

from __future__ import annotations

from typing import Literal, get_args

Method = Literal["oracle", "masked-zero", "labels-only", "dospcot", "reward-model"]
"""What rewards a run's agents learn from (:class:`~dospcot.config.run_configs.TrainConfig`'s ``method``)."""
DEFAULT_VIEWS: tuple[str, ...] = ("coords", "patch")
"""A run's views where its config names none (the grid's)."""
OLD_METHOD_NAMES: dict[str, str] = {"cotrain": "dospcot"}
"""Earlier spellings of a method, still read from older configs and run files."""


def method_name(spelling: str) -> str:
    """``spelling`` as today's code names the method: an earlier spelling (:data:`OLD_METHOD_NAMES`),
    as an older config or a record's ``metrics.csv`` holds it, under its present name."""
    return OLD_METHOD_NAMES.get(spelling, spelling)


Weighting = Literal["hard", "soft"]
"""Self-paced weights: 1 when admitted (SPaMCo's default), or a ramp over the threshold."""
Quota = Literal["label-share", "candidates"]
"""How add_num splits over the reward classes (:mod:`dospcot.core.selection`)."""
LabelStrategy = Literal[
    "uniform",
    "random",
    "outcomes",
    "uncertainty",
    "disagreement",
    "outcomes+disagreement",
    "outcomes+uncertainty",
]
"""How labels are chosen: ``"uniform"`` is the paper's fixed random mask, the others query a rater
(:mod:`dospcot.core.queries`); ``"a+b"`` splits a round's chosen queries equally between a and b."""
EndStateQueries = Literal["random", "spread"]
"""How ``"outcomes"`` picks among the episode ends: at random, or spread over their distinct end states
(:func:`dospcot.core.end_states.spread_ends`)."""
QuerySchedule = Literal["asap", "even", "decay"]
"""How a label budget (``training.label_budget``) spreads over the rounds (:mod:`dospcot.core.queries`)."""
PassKind = Literal["cotrain", "score"]
"""What a pass inside a round does (``training.cotrain_passes``): co-train (fit the classifiers, admit,
age the schedule), or score the steps not yet admitted with the classifiers as they are
(:mod:`dospcot.core.score_passes`)."""
FirstLabels = Literal["round_end", "first_pass"]
"""When a run that learns rewards first co-trains (``training.first_labels``): after round 1's whole
collection, or at round 1's first pass, its labels bought there."""
AgentDraws = Literal["shared", "own"]
"""Whose random draws a run's agents make: the global generators in turn, or each its own
(:mod:`dospcot.core.agent_draws`)."""
PseudoRewards = Literal["classifiers", "hidden"]
"""What an admitted sample's reward is: the consensus class of the views' reward classifiers (DOSPCoT),
or its hidden reward (a control: the same admissions, true rewards)."""
ModelKind = Literal["mlp", "linear"]
LossKind = Literal["cross_entropy", "hinge"]

WEIGHTINGS: tuple[str, ...] = get_args(Weighting)
QUOTAS: tuple[str, ...] = get_args(Quota)
PSEUDO_REWARDS: tuple[str, ...] = get_args(PseudoRewards)
LABEL_STRATEGIES: tuple[str, ...] = get_args(LabelStrategy)
QUERY_SCHEDULES: tuple[str, ...] = get_args(QuerySchedule)
CLASSIFIER_STRATEGIES: tuple[str, ...] = ("uncertainty", "disagreement")
"""The strategies that read the views' reward classifiers to choose their queries (a combination
reads them when one of its parts does)."""
NUMERICS_VERSIONS: tuple[int, ...] = (1, 2, 3)
"""The numerics versions of the reward classifiers' fits (:data:`dospcot.core.self_paced.NUMERICS`)."""
MODEL_KINDS: tuple[str, ...] = get_args(ModelKind)
LOSS_KINDS: tuple[str, ...] = get_args(LossKind)
