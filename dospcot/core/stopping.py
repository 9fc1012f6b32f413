"""When a run stops before its last round: the greedy evaluation's patience
(``training.stop_patience``), beside the co-trainer's own rule (``cotraining.tol``,
``stop_when_fully_admitted``). A run's ``summary.json`` says which fired (``stopped_because``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CO_TRAINER_STOPPED = "the co-trainer's stopping rule (cotraining.tol or every sample admitted)"
"""Why a run stopped where the co-trainer's rule fired."""


@dataclass
class GreedyPatience:
    """Counts the rounds since the agents' greedy evaluation last reached a new best: mean success over
    the agents first, then mean normalised score (a run whose agents all fail still improves as
    their returns rise). The co-training rounds' counterpart of SB3's
    ``StopTrainingOnNoModelImprovement``, which ends one agent's training.

    :param patience: rounds without a new best after which the run stops; 0: never.
    """

    patience: int
    best: tuple[float, float] | None = None
    """The best (mean success, mean normalised score) so far."""
    since_best: int = 0
    """Rounds since :attr:`best` was reached."""

    def update(self, rows: list[dict]) -> bool:
        """Take a round's records (one per agent); return whether the patience ran out."""
        greedy = tuple(float(np.nanmean([r[key] for r in rows])) for key in ("success", "normalised_score"))
        if self.best is None or greedy > self.best:
            self.best, self.since_best = greedy, 0
        else:
            self.since_best += 1
        return bool(self.patience) and self.since_best >= self.patience

    def reason(self) -> str:
        """Why a run stopped where the patience ran out."""
        return f"no new best greedy evaluation in {self.patience} rounds (training.stop_patience)"
