"""Score passes inside a round (``training.pass_kind = "score"``): the classifiers as the last
co-training left them pseudo-reward the steps it did not admit, at the least score each view admitted
each class at, with no fit."""

import pickle
from functools import partial
from typing import Any

import numpy as np
import pytest
import torch as th
from small_runs import PINNED, grid_config, grid_run

from dospcot.config.errors import ConfigError
from dospcot.config.learning_sections import CoTrainingConfig
from dospcot.core.reward_model import RewardModelTrainer
from dospcot.core.score_passes import admission_bounds, score_run
from dospcot.core.self_paced import RunCoTrainer, RunPool
from dospcot.envs import GridWorld, grid_views
from dospcot.tasks import load_config

LAYOUT = GridWorld(size=6, layout_seed=0).layout


def test_a_views_bound_is_the_least_score_it_admitted_each_class_at():
    scores = np.array([[[0.9, 0.1], [0.6, 0.4], [0.3, 0.7], [0.2, 0.8], [0.45, 0.55]]])
    admitted = np.array([[True, True, False, True, False]])
    # class 0: samples 0 and 1 (0.9, 0.6); class 1: sample 3 alone (0.8); 2 and 4 were not admitted
    assert np.allclose(admission_bounds(scores, admitted), [[0.6, 0.8]])
    assert np.isnan(admission_bounds(scores, admitted & (scores.argmax(-1) == 0))[0, 1])


def _pool(x: np.ndarray, n_labelled: int) -> RunPool:
    """Samples ``x`` (N, 3), the first ``n_labelled`` labelled by the sign of their first feature."""
    labelled = np.arange(len(x)) < n_labelled
    label_class = np.where(labelled, (x[:, 0] > 0).astype(np.int64), -1)
    return RunPool([x, -x], labelled, label_class, ~labelled, np.ones(2, bool))


def test_a_pass_admits_what_the_classifiers_are_as_sure_of_as_of_what_they_admitted_and_fits_nothing():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 3))
    trainer = RunCoTrainer([3, 3], CoTrainingConfig(add_fraction_start=0.25), seed=0, n_classes=2)
    step = trainer.step(_pool(x, 8))
    admitted = np.flatnonzero(step.pseudo_weight > 0)
    assert 0 < admitted.size < 32
    params = [p.clone() for clf in trainer.classifiers for p in clf.parameters()]
    # Three new samples: a copy of an admitted one, one every view is unsure of, and an unlabelled copy
    # of the label farthest from the classes' boundary (the sign of the first feature).
    far = np.abs(x[:8, 0]).argmax()
    new = np.vstack([x[admitted[0]], np.zeros(3), x[far]])
    pseudo_class, weight = score_run(trainer, _pool(np.vstack([x, new]), 8))
    assert pseudo_class[40] == step.pseudo_class[admitted[0]] and weight[40] == 1.0
    assert pseudo_class[41] == -1 and weight[41] == 0.0  # scores of 0.5 lie below every bound
    assert pseudo_class[42] == int(x[far, 0] > 0)  # a step is scored whatever the samples beside it
    # what the last step admitted, and every label, keeps the step's entries: the pass leaves them out
    assert (pseudo_class[admitted] == -1).all() and (weight[:8] == 0).all()
    after = [p for clf in trainer.classifiers for p in clf.parameters()]
    assert all(th.equal(a, b) for a, b in zip(params, after, strict=True))
    assert trainer.batch.round == 1


def test_a_pass_needs_a_step_first():
    trainer = RunCoTrainer([3, 3], CoTrainingConfig(), seed=0, n_classes=2)
    with pytest.raises(ValueError, match="needs a co-trainer that has taken a step"):
        score_run(trainer, _pool(np.ones((4, 3)), 2))


def test_a_reward_models_pass_rewards_the_samples_met_since_its_fit_and_fits_nothing():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 3))
    trainer = RewardModelTrainer([3, 3], CoTrainingConfig(ensemble_size=3), seed=0, n_classes=2)
    with pytest.raises(ValueError, match="needs a reward model that has taken a step"):
        trainer.score(_pool(x, 8))
    trainer.step(_pool(x, 8))
    params = [p.clone() for clf in trainer.classifiers for p in clf.parameters()]
    pool = _pool(np.vstack([x, rng.normal(size=(3, 3))]), 8)
    pseudo_class, weight = trainer.score(pool)
    # The six members' (two views, three each) mean probabilities, as the step rewards every sample.
    expected = trainer.probabilities(pool).mean(axis=0).argmax(axis=-1)
    assert np.array_equal(pseudo_class[40:], expected[40:]) and (weight[40:] == 1.0).all()
    assert (pseudo_class[:40] == -1).all() and (weight[:40] == 0).all()  # the step rewarded those
    after = [p for clf in trainer.classifiers for p in clf.parameters()]
    assert all(th.equal(a, b) for a, b in zip(params, after, strict=True))


def _run(
    kind: str, pseudo_rewards: str = "classifiers", seed: int = 3, method: str = "dospcot", **training: Any
):
    training = {"rounds": 2, "steps_per_round": 300, "label_fraction": 0.2, "cotrain_passes": 3, **training}
    cfg = grid_config(
        method,
        ("dqn", "dqn"),
        ("coords", "patch"),
        seed,
        training={**training, "pass_kind": kind},
        cotraining={"pseudo_rewards": pseudo_rewards},
        env={"max_episode_steps": 36},
        dqn={"learning_starts": 50, "buffer_size": 5_000, "net_arch": [32]},
    )
    return grid_run(cfg, partial(GridWorld, LAYOUT), grid_views(LAYOUT, patch_size=3))


def test_a_round_co_trains_once_and_scores_between_its_parts_from_round_2():
    """Three parts a round: two score passes and the round's co-training. Round 1's passes come before
    any co-training and admit nothing; round 2's first pass admits steps taken since round 1's, which
    the agents learn from in the round's next parts; the schedule ages a round per round."""
    run = _run("score")
    passes, fits = [], []
    score_pass, cotrain = run.score_pass, run.cotrain

    def spy_score() -> None:
        before = run.table.weight.copy()
        params = [p.clone() for clf in run.trainer.classifiers for p in clf.parameters()]
        score_pass()
        after = [p for clf in run.trainer.classifiers for p in clf.parameters()]
        assert all(th.equal(a, b) for a, b in zip(params, after, strict=True))
        grown = np.flatnonzero(run.table.weight[: before.size] != before)
        assert (before[grown] == 0).all()  # a pass writes only what was not admitted
        passes.append((run.agents[0].num_timesteps, int((run.table.weight > 0).sum()), len(grown)))

    def spy_cotrain(record: bool = True) -> dict:
        fits.append((run.agents[0].num_timesteps, record))
        return cotrain(record)

    run.score_pass, run.cotrain = spy_score, spy_cotrain
    records = run.run()
    assert [p[0] for p in passes] == [100, 200, 400, 500] and fits == [(300, True), (600, True)]
    assert passes[0][1] == 0 and passes[1][1] == 0  # nothing admitted in round 1 before its co-training
    assert passes[2][2] > 0  # round 2's first pass admits steps round 1's co-training had not
    assert run.trainer.batch.round == 2 and run.trainer.batch.age == 2
    assert [r["round"] for r in records] == [1, 1, 2, 2] and all(r["env_steps"] == 600 for r in records[2:])


def test_round_1s_first_labels_at_its_first_pass_reward_its_later_steps_within_the_round():
    """``first_labels = "first_pass"``: round 1's first pass co-trains on the labels met by then, a fit
    ahead of the round's step of the schedule, so round 1's next score pass admits steps; the round's
    co-training and round 2 run as before."""
    run = _run("score", first_labels="first_pass")
    passes, fits = [], []
    score_pass, cotrain = run.score_pass, run.cotrain

    def spy_score() -> None:
        score_pass()
        passes.append((run.agents[0].num_timesteps, int((run.table.weight > 0).sum())))

    def spy_cotrain(record: bool = True, ages: bool = True) -> dict:
        fits.append((run.agents[0].num_timesteps, record, ages))
        return cotrain(record, ages)

    run.score_pass, run.cotrain = spy_score, spy_cotrain
    run.run()
    assert fits == [(100, False, False), (300, True, True), (600, True, True)]
    assert [p[0] for p in passes] == [200, 400, 500]
    assert passes[0][1] > 0  # round 1's second part is rewarded before the round ends
    assert run.trainer.batch.round == 3 and run.trainer.batch.age == 2  # the early fit aged nothing


def test_round_1s_labels_are_bought_at_its_first_pass_among_the_samples_met_by_then():
    budget = {"label_strategy": "outcomes", "label_budget": 20, "query_schedule": "even"}
    run = _run("score", first_labels="first_pass", **budget)
    bought, buy_labels = [], run.buy_labels

    def spy_buy() -> None:
        buy_labels()
        bought.append((run.agents[0].num_timesteps, int(run.queries.revealed.sum())))

    run.buy_labels = spy_buy
    run.run()
    # Round 1's allowance (half of 20) at its first pass; its end finds nothing left; round 2 the rest.
    assert bought == [(100, 10), (300, 10), (600, 20)]
    round_1 = [row["sample"] for row in run.queries.log if row["round"] == 1]
    assert len(round_1) == 10 and (run.queries.met_round[round_1] == 1).all()


@pytest.mark.parametrize(
    ("keys", "message"),
    [
        ({"cotrain_passes": 1}, "set cotrain_passes >= 2 and passes_from_round = 1"),
        ({"passes_from_round": 2}, "set cotrain_passes >= 2 and passes_from_round = 1"),
        ({"label_strategy": "outcomes", "rater": "file"}, "a person's answers cannot pause"),
    ],
)
def test_first_labels_at_the_first_pass_needs_a_pass_in_round_1_and_the_simulated_rater(keys, message):
    with pytest.raises(ConfigError, match=message):
        _run("score", first_labels="first_pass", **keys)


def test_a_reward_model_run_rewards_every_step_met_since_the_last_fit_at_each_pass():
    run = _run("score", method="reward-model")
    run.run(until_round=1)
    fitted = run.task.pool(run.trainer.dtype_np).unlabelled  # the keys round 1's fit rewarded
    before = run.table.weight.copy()
    for agent in run.agents:
        agent.learn(100, reset_num_timesteps=False)
    run.score_pass()
    now = run.task.pool(run.trainer.dtype_np).unlabelled
    since = np.flatnonzero(now & ~fitted)  # the grid's pool holds every key; these were first met since
    assert since.size > 0 and (before[since] == 0).all() and (run.table.weight[since] == 1.0).all()
    assert np.array_equal(run.table.weight[fitted], before[fitted])  # what the fit rewarded stands


def test_under_the_true_rewards_control_a_pass_writes_the_hidden_rewards():
    run = _run("score", "hidden")
    run.run(until_round=1)
    before = run.table.weight.copy()
    for agent in run.agents:
        agent.learn(100, reset_num_timesteps=False)
    run.score_pass()
    written = np.flatnonzero(run.table.weight[: before.size] != before)
    assert written.size > 0
    assert np.allclose(run.table.reward[written], run.store.hidden_reward[written])


def test_a_run_resumed_from_its_checkpoint_scores_as_the_run_it_continues():
    first = _run("score")
    first.run_round()
    state = pickle.dumps(first.state_dict())  # before another run is built: that re-seeds the globals
    first.run_round()
    resumed = _run("score")
    resumed.load_state_dict(pickle.loads(state))
    resumed.run_round()
    assert np.array_equal(first.table.reward, resumed.table.reward)
    assert np.array_equal(first.table.weight, resumed.table.weight)


def test_score_passes_serve_the_methods_that_learn_rewards_alone():
    assert load_config("grid16-reward-model", ['training.pass_kind="score"']).training.pass_kind == "score"
    with pytest.raises(ConfigError, match='method = "oracle" never reads it'):
        load_config("grid16-oracle", ['training.pass_kind="score"'])
    assert load_config("grid16-dospcot", PINNED).training.pass_kind == "cotrain"
