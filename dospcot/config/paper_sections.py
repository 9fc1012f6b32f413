"""The seed paper's protocol's section (``[tabular]`` of a ``task = "paper"`` config): the
hyperparameters every tabular run of the protocol shares, with its own self-paced schedule."""

from __future__ import annotations

from dataclasses import dataclass, field

from dospcot.config.checks import check_label_fraction, check_within
from dospcot.config.learning_sections import CoTrainingConfig


@dataclass(frozen=True)
class TabularConfig:
    """Hyperparameters shared by every run of a study.

    :param rounds: co-training rounds (each one a collection of ``episodes_per_round`` episodes).
    :param episodes_per_round: episodes each agent plays per round.
    :param replay_sweeps: synchronous TD sweeps over the store after each round's co-training.
    :param label_fraction: share of labelled (s, a) keys, in (0, 1].
    :param cotraining: the self-paced schedule (its consensus weight is replaced by each run's gamma).
    :param learning_rate: TD step size.
    :param discount: discount factor (also the one value iteration uses for the optimum).
    :param eps_start: exploration rate at pace 0.
    :param eps_end: exploration rate at pace 1; eps(p) = eps_start + (eps_end - eps_start) * p.
    """

    rounds: int = 5
    episodes_per_round: int = 500
    replay_sweeps: int = 1
    label_fraction: float = 0.1
    cotraining: CoTrainingConfig = field(default_factory=lambda: CoTrainingConfig(numerics=1))
    learning_rate: float = 0.8
    discount: float = 0.95
    eps_start: float = 0.1
    eps_end: float = 0.1

    def __post_init__(self) -> None:
        check_label_fraction(self.label_fraction)
        if not 0 < self.learning_rate <= 1 or not 0 < self.discount <= 1:
            raise ValueError(
                f"learning_rate and discount must lie in (0, 1], got {self.learning_rate}, {self.discount}"
            )
        if self.rounds < 1 or self.episodes_per_round < 1 or self.replay_sweeps < 0:
            raise ValueError(
                f"rounds and episodes_per_round must be >= 1 and replay_sweeps >= 0; got {self.rounds}, "
                f"{self.episodes_per_round}, {self.replay_sweeps}"
            )
        check_within(self, 0, 1, "eps_start", "eps_end")
        if self.cotraining.numerics != 1:
            raise ValueError(
                "cotraining.numerics: the paper protocol's batched co-trainer fits in numerics 1; set "
                "numerics = 1 in [tabular.cotraining]"
            )
        if self.cotraining.pseudo_rewards != "classifiers":
            raise ValueError(
                "cotraining.pseudo_rewards: the paper protocol's batched co-trainer gives the classifiers' "
                "pseudo-rewards only; the true-rewards control runs under dospcot train"
            )
