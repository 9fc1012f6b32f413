"""The greedy evaluation's patience: rounds without a new best, counted once a round's agents have
beaten a random policy."""

import math

from dospcot.core.stopping import GreedyPatience

RANDOM_RETURN = 0.1
"""A random policy's mean return on the hand-made task below."""


def _round(success: float, score: float, greedy_return: float) -> list[dict]:
    """One round's records of two agents whose evaluations average to the three figures."""
    return [
        {"success": success - 0.05, "normalised_score": score, "greedy_return": greedy_return - 0.02},
        {"success": success + 0.05, "normalised_score": score, "greedy_return": greedy_return + 0.02},
    ]


def test_the_count_waits_for_a_round_that_beats_a_random_policy():
    """A sparse task's first rounds show nothing, or a lucky success from a policy that returns less
    than a random one: they do not spend the patience. Once a round's return beats the random
    policy's, two rounds without a new best stop the run."""
    patience = GreedyPatience(2, RANDOM_RETURN)
    early = [(0.05, -0.1, 0.05), (0.05, -0.1, 0.05), (0.1, -0.05, 0.08), (0.05, -0.1, 0.05)]
    assert not any(patience.update(_round(*r)) for r in early)
    assert patience.since_best == 0 and not patience.learned and patience.best == (0.1, -0.05)
    later = [(0.3, 0.2, 0.3), (0.5, 0.4, 0.5), (0.4, 0.3, 0.4), (0.5, 0.4, 0.5)]
    assert [patience.update(_round(*r)) for r in later] == [False, False, False, True]
    assert patience.best == (0.5, 0.4) and patience.learned


def test_an_unknown_score_leaves_the_return_to_say_when_learning_began():
    """Without ``max_return`` the normalised score is NaN: the greedy return against the random
    policy's still says when the count starts, and a NaN never makes a round a new best."""
    patience = GreedyPatience(1, RANDOM_RETURN)
    assert not any(patience.update(_round(0.05, math.nan, 0.0)) for _ in range(5))
    assert not patience.update(_round(0.6, math.nan, 0.6))
    assert patience.update(_round(0.6, math.nan, 0.6))


def test_the_state_round_trips_and_an_older_checkpoint_counts_every_round():
    patience = GreedyPatience(3, RANDOM_RETURN)
    patience.update(_round(0.5, 0.4, 0.5))
    patience.update(_round(0.4, 0.3, 0.4))
    restored = GreedyPatience(3, RANDOM_RETURN)
    restored.load_state(patience.state())
    assert restored.state() == patience.state() == ((0.5, 0.4), 1, True)
    older = GreedyPatience(3, RANDOM_RETURN)
    older.load_state(((0.0, -0.1), 2))  # written before the count waited for a random policy's return
    assert older.learned and older.update(_round(0.0, -0.1, 0.0))


def test_without_patience_a_run_never_stops():
    patience = GreedyPatience(0)
    assert not any(patience.update(_round(s, 0.5, s)) for s in (0.9, 0.5, 0.3, 0.1))
