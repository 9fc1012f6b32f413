"""The seeds a run derives (dospcot/seeding.py): SeedSequence's, pinned because every record trained
since the derivation moved to SeedSequence depends on them, and distinct where two streams of one
run, or of the studies' runs, would otherwise share one."""

import numpy as np
import pytest

from dospcot.seeding import (
    EVAL_SEED,
    agent_seed,
    bootstrap_seed,
    classifier_seed,
    demonstration_seed,
    ensemble_seed,
    layer_seed,
    round_reset_seed,
)


def _sequence_word(seed: int, *spawn_key: int) -> int:
    return int(np.random.SeedSequence(seed, spawn_key=spawn_key).generate_state(1)[0])


def test_every_derivation_is_the_first_word_of_a_seed_sequence_with_its_stream_tag():
    assert agent_seed(3, 1) == _sequence_word(3, 0, 1) == 3271219438
    assert round_reset_seed(3, 1, 2) == _sequence_word(3, 1, 1, 2) == 3114215830
    assert classifier_seed(3, 1) == _sequence_word(3, 2, 1) == 4074753535
    assert layer_seed(304, 10, 3) == _sequence_word(304, 3, 10, 3) == 836832709
    assert demonstration_seed(2) == _sequence_word(2, 4) == 2478801236


def test_streams_are_told_apart_by_their_tag_not_only_by_their_index():
    # Agent 1 and classifier 1 of one run, or round 0 of agent 1 and agent 1 itself, must not share a
    # seed just because their indices match.
    assert agent_seed(5, 1) != classifier_seed(5, 1)
    assert round_reset_seed(5, 1, 0) != agent_seed(5, 1)


def test_no_seed_repeats_across_the_studies_runs_or_meets_an_evaluation_episode():
    runs, agents, rounds = range(50), range(3), range(1, 31)
    streams = [
        [agent_seed(s, k) for s in runs for k in agents],
        [round_reset_seed(s, k, r) for s in runs for k in agents for r in rounds],
        [classifier_seed(s, j) for s in runs for j in agents],
        [demonstration_seed(s) for s in runs],
        [ensemble_seed(s, j, e) for s in runs for j in agents for e in range(5)],
        [bootstrap_seed(s, r) for s in runs for r in rounds],
    ]
    for stream in streams:
        assert len(set(stream)) == len(stream)
    every = [x for stream in streams for x in stream]
    assert len(set(every)) == len(every)
    evaluation = set(range(EVAL_SEED, EVAL_SEED + 1000))
    assert not evaluation & set(every)
    assert all(0 <= x < 2**32 for x in every)  # numpy's legacy seeding, which SB3 calls, needs this


def test_a_negative_seed_is_refused_with_one_line():
    with pytest.raises(ValueError, match="a seed must be >= 0, got -1"):
        agent_seed(-1, 0)
