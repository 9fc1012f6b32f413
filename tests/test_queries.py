"""Active reward queries on small pools worked by hand: the budget, each strategy's choice, the raters."""

from __future__ import annotations

import csv
import math
from functools import partial

import gymnasium as gym
import numpy as np
import pytest
from small_runs import PINNED
from test_highway import TINY as HIGHWAY_TINY
from test_neural_cotraining import assert_same_learners

from dospcot.adapters.grid_adapter import GridAdapter
from dospcot.adapters.sensor_adapter import SensorAdapter
from dospcot.cli import main
from dospcot.config.errors import ConfigError
from dospcot.core.queries import (
    RewardQueries,
    SimulatedRater,
    choose_queries,
    disagreement_order,
    margins,
    outcome_order,
    query_budget,
    spread_ends,
)
from dospcot.core.sb3_round import CoTrainingRun
from dospcot.envs import GridWorld
from dospcot.envs.masked_highway import make_masked_highway
from dospcot.raters.file_rater import FileRater, QueriesPending, RaterError
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config
from dospcot.tasks.grid import grid_world

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
        "uncertainty",
        np.ones(4, bool),
        2,
        np.random.default_rng(0),
        random_share=0.0,
        probabilities=PROBABILITIES,
    )
    assert ids.tolist() == [3, 1] and not drawn.any()


def test_disagreement_queries_the_most_confident_disagreements_then_the_uncertain_rest():
    # Predicted classes: view 0 (0, 0, 1, 0), view 1 (0, 1, 2, 0): samples 1 and 2 disagree, with mean
    # confidence (0.4 + 0.5) / 2 = 0.45 and (0.8 + 0.8) / 2 = 0.8; then 3 (margin 0.05), then 0 (0.4).
    assert disagreement_order(PROBABILITIES).tolist() == [2, 1, 3, 0]
    candidates = np.array([True, True, False, True])  # sample 2 is labelled already
    ids, _ = choose_queries(
        "disagreement",
        candidates,
        2,
        np.random.default_rng(0),
        random_share=0.0,
        probabilities=PROBABILITIES,
    )
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


NO_LABELS = np.zeros(0, dtype=np.int64)


def _sparse_ends(n_ends: int = 200, goal: int = 137) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sparse task's pool worked by hand: 400 samples, the first ``n_ends`` ended their episode, one
    of them (``goal``) in a state of its own; the others fell into one of ten holes. Returns
    terminated, each end's state key, and its state's features (a one-hot cell of a 4 x 4 map)."""
    terminated = np.arange(400) < n_ends
    keys = np.where(terminated, np.arange(400) % 10, -1)
    keys[goal] = 15
    features = np.zeros((400, 16))
    features[terminated, keys[terminated]] = 1.0
    return terminated, keys, features


def test_outcomes_ask_about_a_rare_end_state_in_the_first_round_where_chance_would_miss_it():
    terminated, keys, features = _sparse_ends()
    candidates, truncated = np.ones(400, bool), np.zeros(400, bool)
    hits = {"keys": 0, "features": 0, "at random": 0}
    for seed in range(20):
        for name, states in (("keys", keys), ("features", features), ("at random", None)):
            end_states = None if states is None else states.__getitem__
            # 12 queries, 20% at random: 10 chosen, a floor of ceil(10 / 2) = 5 on the episode ends.
            ids, drawn = choose_queries(
                "outcomes",
                candidates,
                12,
                np.random.default_rng(seed),
                random_share=0.2,
                terminated=terminated,
                truncated=truncated,
                end_states=end_states,
                labelled=np.zeros(400, bool),
            )
            asked_ends = ids[~drawn & terminated[ids]]
            assert asked_ends.size == 5
            hits[name] += 137 in asked_ends
            if states is not None:  # the goal first (the rarest state), then four holes, none twice
                assert asked_ends[0] == 137 and len(set(keys[asked_ends].tolist())) == 5
    # Five draws among 200 ends find the goal with probability 1 - C(199, 5) / C(200, 5) = 2.5%.
    assert hits == {"keys": 20, "features": 20, "at random": hits["at random"]}
    assert hits["at random"] <= 2


def test_spread_ends_is_fixed_by_its_seed_and_not_by_the_order_of_the_ends():
    _, keys, features = _sparse_ends()
    ends = np.arange(200)
    for states in (keys, features):
        first = spread_ends(ends, 30, states.__getitem__, NO_LABELS, np.random.default_rng(4))
        again = spread_ends(ends[::-1].copy(), 30, states.__getitem__, NO_LABELS, np.random.default_rng(4))
        assert first.tolist() == again.tolist() and len(set(first.tolist())) == 30
    # Keys and features tell the same states apart: the same states, level by level.
    by_keys = keys[spread_ends(ends, 30, keys.__getitem__, NO_LABELS, np.random.default_rng(4))]
    by_features = keys[spread_ends(ends, 30, features.__getitem__, NO_LABELS, np.random.default_rng(4))]
    assert sorted(by_keys[:11].tolist()) == sorted(by_features[:11].tolist()) == [*range(10), 15]


def test_fewer_distinct_end_states_than_queries_repeat_a_state_only_after_every_state_was_asked():
    keys = np.array([7, 7, 7, 7, 7, 3, 3, 3, 9])  # three states: 7 (five ends), 3 (three), 9 (one)
    chosen = spread_ends(np.arange(9), 9, keys.__getitem__, NO_LABELS, np.random.default_rng(0))
    asked = keys[chosen].tolist()
    # Level by level, the fewest candidates first within a level: 9, 3, 7; then 3, 7; then 3, 7; 7, 7.
    assert asked == [9, 3, 7, 3, 7, 3, 7, 7, 7] and sorted(chosen.tolist()) == list(range(9))
    # Features that agree to 6 decimals are one state; a farther state comes before a nearer one.
    points = np.array([[0.0, 0.0], [1e-9, 0.0], [0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    chosen = spread_ends(np.arange(5), 5, points.__getitem__, NO_LABELS, np.random.default_rng(0))
    # The mean is (1.2, 0): the state at 5 is farthest, then the one at 0 (farther from 5 than 1 is).
    assert chosen[:3].tolist()[0] == 4 and chosen[1] in (0, 1, 2) and chosen[2] == 3


def test_end_states_a_label_has_shown_wait_for_those_no_label_has():
    keys = np.array([0, 0, 1, 1, 2, 2, 5, 5])
    # Samples 0 and 2 are labelled (states 0 and 1); the candidates are the rest.
    chosen = spread_ends(
        np.array([1, 3, 4, 5, 6, 7]), 6, keys.__getitem__, np.array([0, 2]), np.random.default_rng(0)
    )
    assert set(keys[chosen[:2]].tolist()) == {2, 5} and set(keys[chosen[2:4]].tolist()) == {0, 1}
    # From features, a state near a labelled one waits for one far from every label.
    points = np.array([[0.0], [0.1], [3.0], [3.1]])
    chosen = spread_ends(np.array([1, 2, 3]), 3, points.__getitem__, np.array([0]), np.random.default_rng(0))
    assert chosen[0] in (2, 3) and chosen[1] == 1


class _EndsPool:
    """A queried task over :func:`_sparse_ends`'s pool, every sample met from round 1."""

    def __init__(self) -> None:
        self.terminated, self.keys, _ = _sparse_ends()
        self.hidden = np.where(self.keys == 15, 1.0, 0.0)
        self.labels = np.zeros(400, bool)

    def met(self) -> np.ndarray:
        return np.ones(400, bool)

    def labelled(self) -> np.ndarray:
        return self.labels.copy()

    def episode_ends(self) -> tuple[np.ndarray, np.ndarray]:
        return self.terminated.copy(), np.zeros(400, bool)

    def end_states(self, ids: np.ndarray) -> np.ndarray:
        return self.keys[ids]

    def describe(self, sample: int) -> dict:
        return {"sample": sample}

    def reveal(self, ids: np.ndarray, rewards: np.ndarray) -> None:
        self.labels[ids] = True


def test_across_rounds_the_ends_go_to_states_no_earlier_round_asked_about():
    training = load_config(
        "tiny",
        [
            'training.label_strategy="outcomes"',
            'training.query_end_states="spread"',
            "training.label_budget=36",
            "training.rounds=3",
            'training.query_schedule="even"',
        ],
    ).training
    pool = _EndsPool()
    queries = RewardQueries(training, SimulatedRater(lambda ids: pool.hidden[ids]))
    states: list[list[int]] = []
    for round_ in (1, 2, 3):
        queries.buy(round_, pool, lambda: None, np.random.default_rng(round_))
        rows = [row for row in queries.log if row["round"] == round_ and row["strategy"] == "outcomes"]
        states.append([int(pool.keys[row["sample"]]) for row in rows if pool.terminated[row["sample"]]])
    # 12 a round, 10 chosen, 5 on ends: the goal and four holes, then the next five holes (and any
    # hole a random query had labelled waits), then the states asked least.
    assert states[0][0] == 15 and len(set(states[0])) == 5
    assert not set(states[1]) & set(states[0]) and len(set(states[1])) == 5
    assert queries.answers_of(1).max() == 1.0


def test_a_random_share_of_every_active_strategys_queries_is_drawn_at_random():
    candidates = np.ones(4, bool)
    ids, drawn = choose_queries(
        "uncertainty",
        candidates,
        4,
        np.random.default_rng(0),
        random_share=0.25,
        probabilities=PROBABILITIES,
    )
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
    header = "sample,key,reward,confirm_new,rewards_seen"
    assert lines == [header, "7,s=1 a=3,,,none yet", "3,s=0 a=3,,,none yet"]
    with pytest.raises(RaterError, match=r"line 2: sample '7' has no numeric reward \(''\)"):
        rater.answer(2, ids, [])
    pending.value.path.write_text("sample,key,reward\n7,s=1 a=3,-1\n3,s=0 a=3,nan\n")
    with pytest.raises(RaterError, match="the reward of sample 3 is nan, not finite"):
        rater.answer(2, ids, [])
    pending.value.path.write_text("sample,key,reward\n7,s=1 a=3,-1\n")
    with pytest.raises(RaterError, match=r"1 of its 2 queries have no answer \(e.g. sample 3\)"):
        rater.answer(2, ids, [])
    # No round before: each value is new, and is taken once confirmed.
    pending.value.path.write_text("sample,key,reward,confirm_new\n3,s=0 a=3,0.5,yes\n7,s=1 a=3,-1,\n")
    with pytest.raises(RaterError, match="line 3: sample 7's reward -1 is new"):
        rater.answer(2, ids, [])
    pending.value.path.write_text("sample,key,reward,confirm_new\n3,s=0 a=3,0.5,yes\n7,s=1 a=3,-1,yes\n")
    assert rater.answer(2, ids, []).tolist() == [-1.0, 0.5]


# --- Queries in whole runs -------------------------------------------------------------------------

TINY_QUERIES = [*PINNED, "training.label_fraction=0.2"]


def _grid_run(
    strategy: str, *overrides: str, make_env=None, seed: int = 3, share: bool = True
) -> CoTrainingRun:
    """A tiny run asking by ``strategy``. ``share``: with :data:`TINY_QUERIES`' label share, its budget;
    False for ``overrides`` that set a budget counted in labels, which leaves a share unread (refused)."""
    queries = TINY_QUERIES if share else PINNED
    cfg = load_config("tiny", [*queries, f'training.label_strategy="{strategy}"', f"seed={seed}", *overrides])
    if make_env is None:
        return build_run(cfg)
    _, views, _ = grid_world(cfg)
    return CoTrainingRun(GridAdapter(cfg, make_env, views), cfg)


@pytest.mark.parametrize("strategy", ["random", "outcomes", "uncertainty", "disagreement"])
def test_every_strategy_spends_the_uniform_masks_budget_and_never_more(strategy):
    run = _grid_run(strategy)
    spent = []

    def check(run: CoTrainingRun, rows: list[dict]) -> None:
        met = int(run.store.visited.sum())
        revealed = int(run.queries.revealed.sum())
        spent.append(revealed)
        assert revealed == math.ceil(0.2 * met - 1e-9)  # enough candidates: the whole budget, no more
        assert run.store.labelled.sum() == revealed  # no mask share: every label was bought
        assert all(
            row["labelled_steps"] == revealed and row["queries"] == len(run.queries.answers_of(run.round))
            for row in rows
        )

    run.run(on_round=check)
    assert spent[0] < spent[1]  # more keys met, more budget
    log = run.queries.log
    assert len(log) == spent[-1] and {row["sample"] for row in log} == set(
        np.flatnonzero(run.queries.revealed)
    )
    # The answers are the keys' true rewards, and the agents' steps on a bought key read it at weight 1.
    rewards = run.task.mdp.reward.ravel()
    assert all(row["answer"] == rewards[row["sample"]] for row in log)
    bought = np.flatnonzero(run.queries.revealed)
    np.testing.assert_array_equal(run.table.reward[bought], rewards[bought])
    assert (run.table.weight[bought] == 1.0).all()
    strategies = {row["strategy"] for row in log}
    assert strategies == ({"random"} if strategy == "random" else {"random", strategy})


def _unqueried_permuted_grid(queried: np.ndarray, seed: int) -> GridWorld:
    """The tiny grid with the rewards of every key never queried permuted among themselves."""
    env = _tiny_grid()
    keys = np.setdiff1d(np.arange(env.reward.size), queried)
    flat = env.reward.reshape(-1)
    flat[keys] = np.random.default_rng(seed).permutation(flat[keys])
    return env


def _tiny_grid() -> GridWorld:
    return grid_world(load_config("tiny"))[0]()


@pytest.mark.parametrize(
    ("strategy", "agents"),
    [
        ("random", "dqn"),
        ("outcomes", "dqn"),
        ("uncertainty", "esarsa_dqn"),
        ("disagreement", "dqn"),
        ("disagreement", "tabular"),
    ],
)
def test_leakage_permuting_the_hidden_rewards_of_keys_never_queried_changes_nothing(strategy, agents):
    plain = _grid_run(strategy, f'agent="{agents}"')
    plain.run()
    queried = np.flatnonzero(plain.queries.revealed)
    permuted = _unqueried_permuted_grid(queried, 0)
    assert not np.array_equal(permuted.reward, _tiny_grid().reward)
    # SB3 seeds the global generators when an agent is built: build and run one run at a time.
    other = _grid_run(strategy, f'agent="{agents}"', make_env=partial(_unqueried_permuted_grid, queried, 0))
    other.run()
    assert other.queries.log == plain.queries.log
    assert_same_learners(plain, other)


class _ScrambleUnqueried(gym.Wrapper):
    """1 - r as the hidden reward of every step whose store id is not in ``queried`` (a step pool's
    ids are the store's length at each step); the evaluation envs, which have no store, are left alone."""

    def __init__(self, env: gym.Env, queried: set[int]) -> None:
        super().__init__(env)
        self.queried, self.store = queried, None

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if self.store is not None and len(self.store) not in self.queried:
            info = dict(info, hidden_reward=1.0 - info["hidden_reward"])
        return obs, reward, terminated, truncated, info


@pytest.mark.parametrize("strategy", ["outcomes", "disagreement"])
def test_leakage_on_the_fast_highway_scrambling_unqueried_hidden_rewards_changes_nothing(strategy):
    cfg = load_config(
        "fasthighway-dospcot",
        [*HIGHWAY_TINY, "training.label_fraction=0.1", f'training.label_strategy="{strategy}"'],
    )
    plain = build_run(cfg)
    plain.run()
    queried = set(np.flatnonzero(plain.queries.revealed).tolist())
    make = partial(make_masked_highway, cfg.highway.env_id, config=cfg.highway.config, queried=True)
    task = SensorAdapter(cfg, cfg.highway, lambda *args: _ScrambleUnqueried(make(*args), queried))
    for env in task._envs:
        env.env.store = task.store
    other = CoTrainingRun(task, cfg)
    other.run()
    n = len(plain.store)
    assert not np.array_equal(plain.store.hidden_reward[:n], other.store.hidden_reward[:n])
    assert other.queries.log == plain.queries.log
    assert_same_learners(plain, other)


def _write_rows(path, rows: list[dict]) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_a_run_answered_through_files_equals_the_simulated_run(tmp_path, capsys):
    sets = [*TINY_QUERIES, 'training.label_strategy="disagreement"']
    args = ["train", "tiny", "--no-progress", *(a for s in sets for a in ("--set", s))]
    assert main([*args, "--runs-dir", str(tmp_path / "simulated")]) == 0
    assert main([*args, "--set", 'training.rater="file"', "--runs-dir", str(tmp_path / "file")]) == 0
    (run_dir,) = (tmp_path / "file" / "tiny").iterdir()
    rewards = build_run(load_config("tiny")).task.mdp.reward.ravel()
    for round_ in (1, 2):
        out = capsys.readouterr().out
        path = run_dir / "queries" / f"round_{round_}.csv"
        assert f"reward queries wait in {path}" in out and f"dospcot train --resume {run_dir}" in out
        rows = list(csv.DictReader(path.open()))
        assert rows and all(row["reward"] == "" for row in rows)
        # Each query shows the key and the grid drawn as text, the agent as A where the key starts.
        state = int(rows[0]["key"].split(",")[0].removeprefix("state "))
        assert rows[0]["frame"].replace("\n", "")[state] == "A"
        # A bad answer file is one line, and nothing is lost: the resume after it goes on.
        for row in rows:  # a value no earlier round answered is confirmed as new
            row["reward"] = repr(float(rewards[int(row["sample"])]))
            row["confirm_new"] = "yes"
        _write_rows(path, [{**rows[0], "reward": "x"}, *rows[1:]])
        assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert "has no numeric reward ('x')" in err and err.count("\n") == 1
        _write_rows(path, rows)
        assert main(["train", "--resume", str(run_dir), "--no-progress"]) == 0
    (simulated,) = (tmp_path / "simulated" / "tiny").iterdir()
    for name in ("metrics.csv", "summary.json", "queries.csv"):
        assert (run_dir / name).read_bytes() == (simulated / name).read_bytes()


def test_queries_go_beside_demonstrations_and_refuse_what_cannot_query():
    run = _grid_run("uncertainty", "demonstrations.episodes=2", "demonstrations.margin_loss_weight=0")
    demonstrated = run.store.labelled.copy()
    run.run()
    assert not run.queries.revealed[demonstrated].any()  # a demonstrated key is never bought again
    for overrides, message in (
        (['training.label_strategy="disagreement"', 'views=["patch"]'], "two views' classifiers disagree"),
        (
            ['training.label_strategy="random"', 'method="masked-zero"'],
            "queries the rewards co-training needs",
        ),
        (['training.label_strategy="random"', "training.segment_length=3"], "segment labels none"),
    ):
        with pytest.raises(ConfigError, match=message):
            load_config("tiny", overrides)
