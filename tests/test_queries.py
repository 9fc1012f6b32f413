"""Active reward queries on small pools worked by hand: the budget, each strategy's choice, the raters."""

from __future__ import annotations

import numpy as np
import pytest

from dospcot.core.queries import (
    choose_queries,
    disagreement_order,
    margins,
    outcome_order,
    query_budget,
)
from dospcot.core.raters import FileRater, QueriesPending, RaterError, SimulatedRater

# Two views, four samples, three classes.
PROBABILITIES = np.array(
    [
        [[0.6, 0.3, 0.1], [0.4, 0.35, 0.25], [0.1, 0.8, 0.1], [0.5, 0.1, 0.4]],
        [[0.7, 0.2, 0.1], [0.2, 0.5, 0.3], [0.1, 0.1, 0.8], [0.45, 0.45, 0.1]],
    ]
)


def test_the_budget_is_what_the_uniform_mask_reveals_among_the_samples_met():
    assert query_budget(0.1, 25, 0) == 3  # ceil(2.5)
    assert query_budget(0.1, 25, 1) == 2
    assert query_budget(0.1, 20, 2) == 0  # exactly 10%: nothing more
    assert query_budget(0.1, 5, 3) == 0  # never negative


def test_margins_are_the_views_mean_gap_between_their_two_likeliest_classes():
    # View 0: 0.3, 0.05, 0.7, 0.1; view 1: 0.5, 0.2, 0.7, 0.0.
    np.testing.assert_allclose(margins(PROBABILITIES), [0.4, 0.125, 0.7, 0.05])


def test_uncertainty_queries_the_smallest_margins_first():
    ids, drawn = choose_queries(
        "uncertainty", np.ones(4, bool), 2, np.random.default_rng(0), random_share=0.0,
        probabilities=PROBABILITIES,
    )  # fmt: skip
    assert ids.tolist() == [3, 1] and not drawn.any()


def test_disagreement_queries_the_most_confident_disagreements_then_the_uncertain_rest():
    # Predicted classes: view 0 (0, 0, 1, 0), view 1 (0, 1, 2, 0): samples 1 and 2 disagree, with mean
    # confidence (0.4 + 0.5) / 2 = 0.45 and (0.8 + 0.8) / 2 = 0.8; then 3 (margin 0.05), then 0 (0.4).
    assert disagreement_order(PROBABILITIES).tolist() == [2, 1, 3, 0]
    candidates = np.array([True, True, False, True])  # sample 2 is labelled already
    ids, _ = choose_queries(
        "disagreement", candidates, 2, np.random.default_rng(0), random_share=0.0,
        probabilities=PROBABILITIES,
    )  # fmt: skip
    assert ids.tolist() == [1, 3]


def test_outcomes_cover_every_kind_of_step_before_the_rest():
    terminated = np.zeros(9, bool)
    terminated[0] = True
    truncated = np.zeros(9, bool)
    truncated[[4, 5]] = True
    candidates = np.ones(9, bool)
    chosen = outcome_order(candidates, 3, terminated, truncated, np.random.default_rng(1))
    assert chosen[0] == 0 and chosen[1] in (4, 5) and chosen[2] in (1, 2, 3, 6, 7, 8)
    # Seven queries: a floor of ceil(7 / 3) = 3 a kind; the goal kind has one and the time limit two,
    # so the rest take the remaining four.
    chosen = outcome_order(candidates, 7, terminated, truncated, np.random.default_rng(1))
    assert chosen[:3].tolist() == [0, *chosen[1:3]] and set(chosen[1:3]) == {4, 5}
    assert len(set(chosen.tolist())) == 7 and set(chosen[3:]) <= {1, 2, 3, 6, 7, 8}


def test_a_random_share_of_every_active_strategys_queries_is_drawn_at_random():
    candidates = np.ones(4, bool)
    ids, drawn = choose_queries(
        "uncertainty", candidates, 4, np.random.default_rng(0), random_share=0.25,
        probabilities=PROBABILITIES,
    )  # fmt: skip
    assert ids[:3].tolist() == [3, 1, 0] and ids[3] == 2 and drawn.tolist() == [False, False, False, True]
    # Before any classifier was fit, a classifier strategy chooses at random, as "random" always does.
    for strategy, probabilities in (("disagreement", None), ("random", PROBABILITIES)):
        ids, drawn = choose_queries(
            strategy, candidates, 3, np.random.default_rng(0), random_share=0.25, probabilities=probabilities
        )
        assert drawn.all() and len(set(ids.tolist())) == 3


def test_no_more_queries_than_candidates():
    ids, _ = choose_queries(
        "random", np.array([True, False, True]), 5, np.random.default_rng(0), random_share=0
    )
    assert sorted(ids.tolist()) == [0, 2]


def test_the_simulated_rater_answers_from_the_hidden_reward():
    hidden = np.array([0.0, -1.0, 10.0])
    rater = SimulatedRater(lambda ids: hidden[ids])
    assert rater.answer(1, np.array([2, 0]), [{}, {}]).tolist() == [10.0, 0.0]


def test_the_file_rater_writes_the_queries_then_reads_a_persons_answers(tmp_path):
    rater = FileRater(tmp_path / "queries")
    ids = np.array([7, 3])
    with pytest.raises(QueriesPending) as pending:
        rater.answer(2, ids, [{"key": "s=1 a=3"}, {"key": "s=0 a=3"}])
    assert pending.value.count == 2 and pending.value.path == tmp_path / "queries" / "round_2.csv"
    lines = pending.value.path.read_text().splitlines()
    assert lines == ["sample,key,reward", "7,s=1 a=3,", "3,s=0 a=3,"]
    with pytest.raises(RaterError, match=r"line 2: sample '7' has no numeric reward \(''\)"):
        rater.answer(2, ids, [])
    pending.value.path.write_text("sample,key,reward\n7,s=1 a=3,-1\n3,s=0 a=3,nan\n")
    with pytest.raises(RaterError, match="the reward of sample 3 is nan, not finite"):
        rater.answer(2, ids, [])
    pending.value.path.write_text("sample,key,reward\n7,s=1 a=3,-1\n")
    with pytest.raises(RaterError, match=r"1 of its 2 queries have no answer \(e.g. sample 3\)"):
        rater.answer(2, ids, [])
    pending.value.path.write_text("sample,key,reward\n3,s=0 a=3,0.5\n7,s=1 a=3,-1\n")
    assert rater.answer(2, ids, []).tolist() == [-1.0, 0.5]
