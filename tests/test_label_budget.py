"""A label budget counted in answers, spread over the rounds (dospcot/core/queries.py), the strategies'
class floors and combinations, and the reward-model peer (dospcot/core/reward_model.py): schedules
worked by hand, small pools, equal counts across arms, and the leakage test for every new piece."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
from small_runs import PINNED
from test_neural_cotraining import assert_same_learners
from test_queries import PROBABILITIES, _grid_run, _tiny_grid, _unqueried_permuted_grid

from dospcot.config.errors import ConfigError
from dospcot.core.queries import RewardQueries, SimulatedRater, choose_queries, class_floors, scheduled_labels
from dospcot.core.round_records import class_rows, error_dependence
from dospcot.core.self_paced import RunRound
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

BUDGET = ["training.label_budget=30", "training.rounds=3"]
SHORT_BUDGET = ["training.label_budget=20", "training.rounds=2"]
"""Two rounds: enough for a schedule, a round-1 cap and a classifier that chooses in round 2."""


def test_the_schedules_spread_a_budget_of_100_over_5_rounds_as_worked_by_hand():
    def cumulative(schedule: str, cap: float = 1.0) -> list[int]:
        return [scheduled_labels(100, 5, r, schedule, cap) for r in range(1, 6)]

    assert cumulative("asap") == [100] * 5
    assert cumulative("even") == [20, 40, 60, 80, 100]
    # Harmonic numbers H_1..H_5 = 1, 1.5, 1.833, 2.083, 2.283: 100 x H_r / H_5, rounded down.
    assert cumulative("decay") == [43, 65, 80, 91, 100]
    # The round-1 cap holds round 1 back; the schedule after it is unchanged, so round 2 catches up.
    assert cumulative("asap", 0.25) == [25, 100, 100, 100, 100]
    assert cumulative("decay", 0.25) == [25, 65, 80, 91, 100]
    assert cumulative("even", 0.5) == [20, 40, 60, 80, 100]  # a cap above the round's share binds nothing


class _Pool:
    """A queried task over a fixed pool whose met samples grow by hand."""

    def __init__(self, n: int) -> None:
        self.n_met = 0
        self.n = n
        self.labels = np.zeros(n, dtype=bool)
        self.hidden = np.arange(n, dtype=np.float64) % 3

    def met(self) -> np.ndarray:
        return np.arange(self.n) < self.n_met

    def labelled(self) -> np.ndarray:
        return self.labels.copy()

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(self.n, dtype=bool), np.zeros(self.n, dtype=bool)

    def describe(self, sample: int) -> dict:
        return {"sample": sample}

    def reveal(self, ids: np.ndarray, rewards: np.ndarray) -> None:
        self.labels[ids] = True

    def hidden_reward(self, ids: np.ndarray) -> np.ndarray:
        return self.hidden[ids]


def _training(strategy: str = "random", **keys):
    overrides = [f"training.{key}={value!r}".replace("'", '"') for key, value in keys.items()]
    return load_config("tiny", [*PINNED, f'training.label_strategy="{strategy}"', *overrides]).training


def test_unspent_labels_carry_forward_and_the_first_round_cap_holds():
    training = _training(label_budget=12, rounds=3, query_schedule="even", first_round_share=0.25)
    pool = _Pool(100)
    queries = RewardQueries(training, SimulatedRater(pool.hidden_reward))
    bought = []
    for round_, met in ((1, 50), (2, 5 + 50), (3, 100)):
        pool.n_met = met
        queries.buy(round_, pool, lambda: None, np.random.default_rng(round_))
        bought.append(int(queries.revealed.sum()))
    # Even: 4, 8, 12 by round; round 1 capped at floor(0.25 x 12) = 3.
    assert bought == [3, 8, 12]
    # A round with too few candidates carries its shortfall to the next.
    pool = _Pool(100)
    queries = RewardQueries(training, SimulatedRater(pool.hidden_reward))
    counts = []
    for round_, met in ((1, 2), (2, 4), (3, 100)):
        pool.n_met = met
        queries.buy(round_, pool, lambda: None, np.random.default_rng(round_))
        counts.append(int(queries.revealed.sum()))
    assert counts == [2, 4, 12]


def test_class_floors_ask_about_every_predicted_class_rarest_first():
    # One view, five samples: predicted classes 0, 0, 0, 1, 0; margins 0.8, 0.6, 0.2, 0.4, 0.1.
    probabilities = np.array([[[0.9, 0.1], [0.8, 0.2], [0.6, 0.4], [0.3, 0.7], [0.55, 0.45]]])
    candidates = np.ones(5, bool)
    # The rare class 1 first (sample 3), then class 0's least certain (sample 4).
    assert class_floors(candidates, 2, probabilities).tolist() == [3, 4]
    # A floor of 2 a class: class 1 has one sample, so one query of the 4 is left to the strategy.
    assert class_floors(candidates, 4, probabilities).tolist() == [3, 4, 2]
    choose = partial(choose_queries, "uncertainty", candidates, 3, np.random.default_rng(0), random_share=0.0)
    ids, drawn = choose(probabilities=probabilities, class_floor=2 / 3)
    # Two by the floors, then uncertainty's smallest margin among the rest (sample 2).
    assert ids.tolist() == [3, 4, 2] and not drawn.any()
    # Without floors the rare class waits behind the uncertain samples of the common one.
    assert choose(probabilities=probabilities)[0].tolist() == [4, 2, 3]


def test_a_combination_splits_its_chosen_queries_between_its_parts():
    terminated = np.array([True, False, False, False])
    ids, drawn = choose_queries(
        "outcomes+uncertainty",
        np.ones(4, bool),
        2,
        np.random.default_rng(0),
        random_share=0.0,
        probabilities=PROBABILITIES,
        terminated=terminated,
        truncated=np.zeros(4, bool),
    )
    # outcomes takes the episode end (0), uncertainty the smallest margin of the rest (3).
    assert ids.tolist() == [0, 3] and not drawn.any()
    # Before any classifier: outcomes chooses all of the guided share.
    ids, _ = choose_queries(
        "outcomes+disagreement",
        np.ones(4, bool),
        1,
        np.random.default_rng(0),
        random_share=0.0,
        terminated=terminated,
        truncated=np.zeros(4, bool),
    )
    assert ids.tolist() == [0]


def test_confidently_agreed_samples_are_never_queried():
    training = _training("uncertainty", label_budget=4, rounds=1, query_skip_confidence=0.6)
    pool = _Pool(4)
    pool.n_met = 4
    queries = RewardQueries(training, SimulatedRater(pool.hidden_reward))
    queries.buy(1, pool, lambda: PROBABILITIES, np.random.default_rng(0))
    # Both views give sample 0 class 0, at 0.6 and 0.7; sample 3 class 0 too, but at 0.5 and 0.45;
    # samples 1 and 2 split. A budget of 4 buys the three others and stops.
    assert sorted(np.flatnonzero(queries.revealed).tolist()) == [1, 2, 3]


@pytest.mark.parametrize(
    "overrides",
    [
        ['views=["coords", "patch"]'],  # DOSPCoT
        ['views=["coords"]'],  # self-training
        ['method="reward-model"', 'views=["coords"]'],
    ],
)
def test_every_arm_buys_the_same_count_of_labels_whatever_its_agents(overrides):
    strategy = "uncertainty" if "reward-model" not in overrides[0] else "disagreement"
    run = _grid_run(strategy, *BUDGET, 'training.query_schedule="even"', *overrides, share=False)
    per_round = []
    run.run(on_round=lambda r, rows: per_round.append(int(r.queries.revealed.sum())))
    assert per_round == [10, 20, 30]
    assert len(run.queries.log) == 30 and run.store.labelled.sum() == 30


def test_the_reward_model_rewards_every_unlabelled_sample_from_its_ensembles_labels_alone():
    run = _grid_run("disagreement", *SHORT_BUDGET, 'method="reward-model"', 'views=["coords"]', share=False)
    run.run()
    pool = run.task.pool()
    probabilities = run.trainer.probabilities(pool)
    assert probabilities.shape[0] == 3  # one view, three members: the queries' "views"
    admitted = run.table.weight[: pool.unlabelled.size] > 0
    assert admitted[pool.unlabelled].all()  # no self-paced selection: all of U is rewarded
    # The members differ (their own seeds and bootstraps), so disagreement has something to read.
    assert not np.allclose(probabilities[0], probabilities[1])


def test_the_reward_models_error_dependence_compares_its_members():
    run = _grid_run("disagreement", *SHORT_BUDGET, 'method="reward-model"', 'views=["coords"]', share=False)
    rows = run.run_round()
    assert {"joint_error", "independent_error", "disagreement", "error_correlation"} <= set(rows[0])
    stats = run.cotrain()  # another fit on the same pool: the figures read its members' classes
    pool = run.task.pool()
    members = run.trainer.probabilities(pool).argmax(axis=-1)  # (3, N): one view, three members
    expected = error_dependence(members, run.task.true_class(), pool.unlabelled)
    assert expected["disagreement"] > 0
    assert {key: stats[key] for key in expected} == pytest.approx(expected, nan_ok=True)


@pytest.mark.parametrize(
    ("strategy", "overrides"),
    [
        (
            "outcomes+disagreement",
            [
                'training.query_schedule="decay"',
                "training.first_round_share=0.3",
                "training.query_pool_factor=3",
                "training.query_skip_confidence=0.9",
                "cotraining.refit_new_classes=true",
                "env.episode_end_classes=true",
            ],
        ),
        ("uncertainty", ['training.query_schedule="even"', "training.query_class_floor=0.5"]),
        ("disagreement", ['method="reward-model"', 'views=["coords"]', 'training.query_schedule="even"']),
    ],
)
def test_leakage_permuting_unqueried_rewards_changes_nothing_under_budgets_and_the_peer(strategy, overrides):
    plain = _grid_run(strategy, *SHORT_BUDGET, *overrides, share=False)
    plain.run()
    queried = np.flatnonzero(plain.queries.revealed)
    assert not np.array_equal(_unqueried_permuted_grid(queried, 0).reward, _tiny_grid().reward)
    other = _grid_run(
        strategy,
        *SHORT_BUDGET,
        *overrides,
        make_env=partial(_unqueried_permuted_grid, queried, 0),
        share=False,
    )
    other.run()
    assert other.queries.log == plain.queries.log
    assert_same_learners(plain, other)


def test_budget_keys_refuse_what_they_cannot_mean():
    with pytest.raises(ConfigError, match="label_budget counts a rater's answers"):
        load_config("tiny", [*PINNED, "training.label_budget=10"])
    with pytest.raises(ConfigError, match="spread a budget counted in labels: set label_budget"):
        load_config("tiny", [*PINNED, 'training.label_strategy="random"', 'training.query_schedule="even"'])
    with pytest.raises(ConfigError, match="first_round_share must lie in"):
        load_config(
            "tiny",
            ['training.label_strategy="random"', "training.label_budget=5", "training.first_round_share=0"],
        )
    with pytest.raises(ConfigError, match="query_schedule"):
        load_config(
            "tiny",
            ['training.label_strategy="random"', "training.label_budget=5", 'training.query_schedule="soon"'],
        )
    with pytest.raises(ConfigError, match="segment labels need co-training"):
        load_config("tiny", [*PINNED, 'method="reward-model"', "training.segment_length=4"])
    # One view with disagreement is the peer's own: its ensemble's members disagree.
    assert load_config(
        "tiny", ['method="reward-model"', 'views=["coords"]', 'training.label_strategy="disagreement"']
    )


def test_pseudo_rewards_per_class_split_missing_from_wrong_as_worked_by_hand():
    # Six samples met (one more never met); true classes 0, 0, 0, 1, 1, -1 (a value no label showed).
    true_class = np.array([0, 0, 0, 1, 1, -1, 1])
    labelled = np.array([True, False, False, True, False, False, False])
    unlabelled = np.array([False, True, True, False, True, True, False])
    # Sample 1 rightly 0, sample 2 not admitted, sample 4 wrongly 0, sample 5 given 1.
    pseudo_class = np.array([-1, 0, 0, -1, 0, 1, -1])
    weight = np.array([0.0, 1.0, 0.0, 0.0, 0.7, 1.0, 0.0])
    empty = np.zeros((1, 7))
    result = RunRound(
        pseudo_class, weight, empty, empty.astype(int), np.zeros((1, 2)), np.zeros(1), 0.5, 0, False
    )
    rows = {
        row["class"]: row
        for row in class_rows(3, result, labelled, unlabelled, true_class, np.array([-1.0, 5.0]))
    }
    assert sorted(rows) == [-1, 0, 1]  # the never-met sample 6 is in no row
    zero, one, unseen = rows[0], rows[1], rows[-1]
    assert (zero["samples"], zero["labelled"], zero["admitted"]) == (3, 1, 1)
    assert zero["recall"] == 0.5  # of U's two class-0 samples, one was given 0 (the other is missing)
    assert zero["precision"] == 0.5  # of the two given 0, one holds it
    assert (one["reward"], one["samples"], one["labelled"], one["admitted"]) == (5.0, 2, 1, 1)
    assert one["recall"] == 0.0 and one["precision"] == 0.0  # sample 4 got 0; sample 5, given 1, is -1
    assert np.isnan(unseen["reward"]) and unseen["recall"] == 0.0 and np.isnan(unseen["precision"])


def test_the_control_one_view_co_trained_with_every_reward_labelled_is_the_oracle_bit_for_bit():
    """The co-training machinery (reward table, keyed labels, a co-trainer whose U is empty) costs
    nothing when no reward is hidden: exploring by rounds, as the oracle does, the one agent learns
    exactly the oracle's parameters and scores the same every round."""
    common = ['views=["coords"]', "seed=3"]
    oracle = build_run(load_config("tiny", [*PINNED, 'method="oracle"', *common]))
    oracle_rows = oracle.run()
    control = build_run(
        load_config(
            "tiny", [*PINNED, *common, "training.label_fraction=1.0", 'training.exploration="rounds"']
        )
    )
    control_rows = control.run()
    for key in ("greedy_return", "success", "agreement", "eps"):
        assert [r[key] for r in control_rows] == [r[key] for r in oracle_rows], key
    for p, q in zip(oracle.agents[0].policy.parameters(), control.agents[0].policy.parameters(), strict=True):
        assert np.array_equal(p.detach().numpy(), q.detach().numpy())
