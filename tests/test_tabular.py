"""Tabular agents and tabular co-training: targets, leakage, determinism, learning."""

import json

import numpy as np
import pytest

from dospcot import metrics, statistics
from dospcot.core.tabular_runs import TabularConfig, TabularCoTraining, TabularRunSpec
from dospcot.envs import StateActionMask
from dospcot.policies.tabular import TabularAgents, epsilon_greedy_probs, expected_value
from dospcot.run.paper_protocol import cliffwalking_mdp


def test_expected_sarsa_target_with_tied_maxima_by_hand():
    q_next = np.array([[1.0, 3.0, 3.0, 0.0]])
    # eps 0.2: each action eps/4 = .05; the greedy mass .8 split over the two tied maxima.
    assert epsilon_greedy_probs(q_next, 0.2)[0].tolist() == pytest.approx([0.05, 0.45, 0.45, 0.05])
    assert expected_value(q_next, 0.2)[0] == pytest.approx(0.05 * 1 + 0.45 * 3 + 0.45 * 3 + 0.05 * 0)
    agents = TabularAgents(["esarsa"], 2, 4, learning_rate=0.5, discount=0.9, seeds=[0])
    agents.q[0, 1] = q_next[0]
    one = np.array([0])
    agents.update(
        one,
        one,
        np.array([2]),
        np.array([-1.0]),
        np.array([1.0]),
        np.array([1]),
        np.array([False]),
        np.array([0]),
        np.array([0.2]),
    )
    # Q(0, 2) = 0 + .5 * (-1 + .9 * 2.75 - 0) = 0.7375
    assert agents.q[0, 0, 2] == pytest.approx(0.7375)


def test_q_and_sarsa_targets_and_zero_weight():
    agents = TabularAgents(["q", "sarsa", "esarsa"], 2, 2, learning_rate=1.0, discount=1.0, seeds=[0, 1, 2])
    agents.q[:, 1] = [2.0, -4.0]
    slots = np.arange(3)
    agents.update(
        slots,
        np.zeros(3, int),
        np.zeros(3, int),
        np.zeros(3),
        np.array([1.0, 1.0, 0.0]),
        np.ones(3, int),
        np.zeros(3, bool),
        np.array([1, 1, 1]),
        np.full(3, 0.5),
    )
    # Q: max = 2; SARSA: Q(s', a' = 1) = -4; ESARSA with weight 0: unchanged.
    assert agents.q[:, 0, 0].tolist() == [2.0, -4.0, 0.0]


def test_epsilon_greedy_acting_splits_ties_and_explores():
    agents = TabularAgents(["q"], 1, 4, 0.5, 0.9, seeds=[0])
    agents.q[0, 0] = [0.0, 1.0, 1.0, 0.0]
    counts = (
        np.bincount(
            [agents.act(np.array([0]), np.array([0]), np.array([0.2]))[0] for _ in range(20000)], minlength=4
        )
        / 20000
    )
    assert counts == pytest.approx([0.05, 0.45, 0.45, 0.05], abs=0.015)


@pytest.fixture(scope="module")
def mdp():
    return cliffwalking_mdp()


SMALL = TabularConfig(rounds=2, episodes_per_round=60)
ALL_METHODS = [
    TabularRunSpec("dospcot", ("esarsa", "q"), ("coords", "patch"), seed=5),
    TabularRunSpec("dospcot", ("sarsa",), ("patch",), seed=5),
    TabularRunSpec("dospcot", ("esarsa", "esarsa", "q"), ("coords", "patch", "onehot"), seed=5),
    TabularRunSpec("masked-zero", ("esarsa",), ("coords",), seed=5),
    TabularRunSpec("labels-only", ("q",), ("coords",), seed=5),
]


@pytest.fixture(scope="module")
def all_methods(mdp):
    """``ALL_METHODS`` trained once for the module, on ``SMALL``: the runner (its step count) and its
    result. The tests only read it; each compares it with a run of its own."""
    runner = TabularCoTraining(mdp, ALL_METHODS, SMALL)
    return runner, runner.run()


def test_leakage_permuting_hidden_rewards_leaves_q_tables_bit_identical(mdp, all_methods):
    from dataclasses import replace

    masked = ~StateActionMask(mdp.n_states, mdp.n_actions, SMALL.label_fraction, seed=5).labelled
    reward = mdp.reward.copy()
    values = reward[masked]
    reward[masked] = np.random.default_rng(0).permutation(values)
    assert not np.array_equal(reward, mdp.reward)  # the permutation moved some -100s
    permuted = replace(mdp, reward=reward)
    _, a = all_methods
    b = TabularCoTraining(permuted, ALL_METHODS, SMALL).run()
    assert np.array_equal(a.q, b.q)
    # The metrics do read the truth, so they may differ; the learners may not.
    assert [r["pace"] for r in a.records] == [r["pace"] for r in b.records]


def test_same_seed_gives_bit_identical_tables_twice(mdp, all_methods):
    _, a = all_methods
    b = TabularCoTraining(mdp, ALL_METHODS, SMALL).run()
    assert np.array_equal(a.q, b.q)
    assert json.dumps(a.records) == json.dumps(b.records)  # NaN-safe comparison


def test_a_run_is_the_same_alone_or_in_a_batch(mdp):
    batch = [*ALL_METHODS, TabularRunSpec("dospcot", ("esarsa", "q"), ("coords", "patch"), seed=6)]
    together = TabularCoTraining(mdp, batch, SMALL).run()
    alone = TabularCoTraining(mdp, batch[:1], SMALL).run()
    assert np.array_equal(together.q[:2], alone.q)


def test_oracle_q_learning_finds_the_optimal_path(mdp):
    spec = [TabularRunSpec("oracle", ("q",), ("coords",), seed=s) for s in range(3)]
    result = TabularCoTraining(mdp, spec, TabularConfig(rounds=1, episodes_per_round=300)).run()
    assert [r["greedy_return"] for r in result.records] == [-13.0] * 3
    assert all(r["agreement"] == 1.0 for r in result.records)


@pytest.mark.slow
def test_cotraining_learns_the_masked_task_where_masked_zero_fails(mdp):
    seeds = range(4)
    specs = [TabularRunSpec("dospcot", ("esarsa", "esarsa"), ("coords", "patch"), seed=s) for s in seeds]
    specs += [TabularRunSpec("masked-zero", ("esarsa",), ("coords",), seed=s) for s in seeds]
    result = TabularCoTraining(mdp, specs, TabularConfig(rounds=5, episodes_per_round=200)).run()
    last = [r for r in result.records if r["round"] == 5]
    cotrain = np.mean([r["agreement"] for r in last if r["method"] == "dospcot"])
    zero = np.mean([r["agreement"] for r in last if r["method"] == "masked-zero"])
    pseudo = np.mean([r["pseudo_accuracy"] for r in last if r["method"] == "dospcot"])
    assert cotrain > zero + 0.2
    assert pseudo > 0.9


def test_bad_specs_raise():
    with pytest.raises(ValueError, match="method must be one of"):
        TabularRunSpec("co-train", ("q",), ("coords",))
    with pytest.raises(ValueError, match="one view per agent"):
        TabularRunSpec("dospcot", ("q", "q"), ("coords",))
    with pytest.raises(ValueError, match="unknown tabular agent kind 'dqn'"):
        TabularRunSpec("dospcot", ("dqn",), ("coords",))
    with pytest.raises(ValueError, match="label_fraction"):
        TabularConfig(label_fraction=0.0)


def test_unknown_view_in_a_spec_raises(mdp):
    with pytest.raises(ValueError, match=r"unknown view\(s\) \['lidar'\]"):
        TabularCoTraining(mdp, [TabularRunSpec("dospcot", ("q",), ("lidar",))], SMALL)


def test_metrics_by_hand():
    assert statistics.iqm(np.arange(10.0)) == pytest.approx(np.mean(np.arange(2.0, 8.0)))
    low, high = statistics.bootstrap_ci(np.array([1.0, 1.0, 1.0]))
    assert low == high == 1.0
    low, high = statistics.bootstrap_ci(np.arange(100.0))
    assert low < 49.5 < high and high - low < 25
    ref = metrics.paper_reference_policy()
    assert ref.shape == (48,)
    # The data file's own statement: an all-zero Q-table (argmax 0 everywhere) scores 21/48.
    assert metrics.paper_accuracy(np.zeros((1, 48), int), ref)[0] == pytest.approx(21 / 48)


def test_a_run_whose_pool_is_fully_admitted_stops_and_freezes(mdp):
    from dataclasses import replace

    cfg = replace(
        SMALL,
        rounds=3,
        cotraining=replace(SMALL.cotraining, add_fraction_start=10.0, stop_when_fully_admitted=True),
    )
    specs = [
        TabularRunSpec("dospcot", ("esarsa",), ("patch",), seed=1),
        TabularRunSpec("labels-only", ("esarsa",), ("coords",), seed=1),
    ]
    three = TabularCoTraining(mdp, specs, cfg).run()
    one = TabularCoTraining(mdp, specs, replace(cfg, rounds=1)).run()
    first = [r for r in three.records if r["method"] == "dospcot"]
    assert first[0]["coverage"] == 1.0 and [r["active"] for r in first] == [False, False, False]
    assert np.array_equal(three.q[0], one.q[0])  # no learning after the stop
    assert not np.array_equal(three.q[1], one.q[1])  # the baseline run went on
