"""The greedy evaluation's patience: rounds without a new best, counted once an evaluation has beaten
a random policy."""

import math

from dospcot.core.stopping import GreedyPatience


def _round(success: float, score: float) -> list[dict]:
    """One round's records of two agents whose evaluations average to ``success`` and ``score``."""
    return [
        {"success": success - 0.1, "normalised_score": score},
        {"success": success + 0.1, "normalised_score": score},
    ]


def test_the_count_waits_for_an_evaluation_that_beats_a_random_policy():
    """A sparse task's first rounds show nothing (success 0, a score below a random policy's): they
    do not spend the patience; once a round succeeds, two rounds without a new best stop the run."""
    patience = GreedyPatience(2)
    stops = [patience.update(_round(s, x)) for s, x in [(0.0, -0.2), (0.0, -0.3), (0.0, -0.2), (0.0, -0.4)]]
    assert stops == [False] * 4 and patience.since_best == 0 and not patience.learned
    stops = [patience.update(_round(s, x)) for s, x in [(0.3, 0.1), (0.2, 0.4), (0.3, 0.1)]]
    assert stops == [False, False, True]  # 0.3 is the best; the next two rounds bring nothing above it
    assert patience.best == (0.3, 0.1)


def test_an_unknown_score_counts_only_after_a_success():
    """Without ``max_return`` the normalised score is NaN: success alone says when learning began, and
    a NaN never makes a round a new best."""
    patience = GreedyPatience(1)
    assert not any(patience.update(_round(0.0, math.nan)) for _ in range(5))
    assert not patience.update(_round(0.6, math.nan))
    assert patience.update(_round(0.6, math.nan))


def test_without_patience_a_run_never_stops():
    patience = GreedyPatience(0)
    assert not any(patience.update(_round(s, 0.5)) for s in (0.9, 0.5, 0.3, 0.1))
