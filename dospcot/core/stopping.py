"""When a run stops before its last round: the greedy evaluation's patience
(``training.stop_patience``), beside the co-trainer's own rule (``cotraining.tol``,
``stop_when_fully_admitted``). A run's ``summary.json`` says which fired (``stopped_because``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

CO_TRAINER_STOPPED = "the co-trainer's stopping rule (cotraining.tol or every sample admitted)"
"""Why a run stopped where the co-trainer's rule fired."""


@dataclass
class GreedyPatience:
    """Counts the rounds since the agents' greedy evaluation last reached a new best: mean success over
    the agents first, then mean normalised score (a run whose agents all fail still improves as
    their returns rise). The co-training rounds' counterpart of SB3's
    ``StopTrainingOnNoModelImprovement``, which ends one agent's training.

    The count starts once a round's agents have beaten a random policy (their mean greedy return above
    a random policy's): on a sparse task the first rounds often show nothing, or a lucky success from
    a policy that does worse than chance, and a run stopped there would stop before its agents had met
    the reward.

    :param patience: rounds without a new best after which the run stops; 0: never.
    :param random_return: a random policy's mean return on the task (-inf: every round counts).
    """

    patience: int
    random_return: float = -math.inf
    best: tuple[float, float] | None = None
    """The best (mean success, mean normalised score) so far."""
    since_best: int = 0
    """Rounds since :attr:`best` was reached, counted once :attr:`learned`."""
    learned: bool = False
    """Whether some round's mean greedy return has exceeded :attr:`random_return`."""

    def update(self, rows: list[dict]) -> bool:
        """Take a round's records (one per agent); return whether the patience ran out."""
        greedy = tuple(_mean_over_known([r[key] for r in rows]) for key in ("success", "normalised_score"))
        greedy_return = _mean_over_known([r["greedy_return"] for r in rows])
        self.learned = self.learned or greedy_return > self.random_return
        if self.best is None or greedy > self.best:
            self.best, self.since_best = greedy, 0
        elif self.learned:
            self.since_best += 1
        return bool(self.patience) and self.since_best >= self.patience

    def state(self) -> tuple[tuple[float, float] | None, int, bool]:
        """What a checkpoint keeps: :attr:`best`, :attr:`since_best`, :attr:`learned`."""
        return self.best, self.since_best, self.learned

    def load_state(self, state: tuple) -> None:
        """Continue from :meth:`state`; a checkpoint written before :attr:`learned` counted every round."""
        self.best, self.since_best, *learned = state
        self.learned = learned[0] if learned else True

    def reason(self) -> str:
        """Why a run stopped where the patience ran out."""
        return f"no new best greedy evaluation in {self.patience} rounds (training.stop_patience)"


def _mean_over_known(values: list[float]) -> float:
    """The mean of the values that are not NaN; NaN, without numpy's warning, where none is known (a
    normalised score without ``max_return``)."""
    known = [float(v) for v in values if not math.isnan(v)]
    return sum(known) / len(known) if known else math.nan
