"""The seeds a run derives (dospcot/seeding.py): pinned, because every committed record was trained
with them, and distinct where two streams of one run would otherwise share one."""

import numpy as np

from dospcot.seeding import (
    DEMO_SEED,
    agent_seed,
    classifier_seed,
    demonstration_seed,
    layer_seed,
    round_reset_seed,
    tabular_agent_seed,
)


def test_derivations_are_the_ones_the_records_were_trained_with():
    assert agent_seed(3, 1) == 3001
    assert round_reset_seed(3, 1, 2) == 3001 + 2 * 7919
    assert classifier_seed(3, 1) == 304
    assert layer_seed(304, 10, 3) == 304 * 7919 + 310 + 3
    assert demonstration_seed(2) == DEMO_SEED + 20_000
    assert tabular_agent_seed(3, 1) == int(np.random.SeedSequence([3, 1]).generate_state(1)[0])


def test_one_run_never_reuses_a_seed_within_a_stream():
    for seed in (0, 7, 123):
        resets = [round_reset_seed(seed, k, r) for k in range(3) for r in range(1, 101)]
        assert len(set(resets)) == len(resets)
        assert len({agent_seed(seed, k) for k in range(3)}) == 3
        assert len({classifier_seed(seed, j) for j in range(3)}) == 3
        assert len({tabular_agent_seed(seed, k) for k in range(37)}) == 37


def test_runs_of_different_seeds_get_different_agents():
    agents = [agent_seed(s, k) for s in range(50) for k in range(3)]
    classifiers = [classifier_seed(s, j) for s in range(50) for j in range(3)]
    assert len(set(agents)) == len(agents) and len(set(classifiers)) == len(classifiers)
