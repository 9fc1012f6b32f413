"""The co-training core on its own: reward classes, the key pool's features, one SelfPacedCoTrainer
round after another, each against figures worked out by hand."""

import json
from dataclasses import replace

import numpy as np
import pytest

from dospcot.config.learning_sections import CoTrainingConfig
from dospcot.core.key_pool import key_features
from dospcot.core.reward_classes import (
    QuantileRewardClasses,
    RewardClasses,
    RunRewardClasses,
    episode_end_class_mask,
)
from dospcot.core.round_records import error_dependence, record_head, round_stats
from dospcot.core.self_paced import (
    Pool,
    RoundResult,
    RunCoTrainer,
    RunPool,
    RunRound,
    SelfPacedCoTrainer,
)


def test_reward_classes_keep_the_order_of_first_appearance_and_round_trip():
    classes = RewardClasses(n_runs=2, n_classes=3)
    classes.observe(0, np.array([-1.0, -100.0, -1.0]))
    classes.observe(1, np.array([0.0]))
    classes.observe(0, np.array([0.0, -100.0]))  # a new value takes the next free class
    assert classes.values[0].tolist() == [-1.0, -100.0, 0.0]
    assert classes.values[1, 0] == 0.0 and np.isnan(classes.values[1, 1:]).all()
    assert classes.mask.tolist() == [[True, True, True], [True, False, False]]
    rewards = np.array([[-100.0, 0.0, -1.0, 5.0], [0.0, 0.0, -1.0, 0.0]])
    encoded = classes.encode(rewards)
    assert encoded.tolist() == [[1, 2, 0, -1], [0, 0, -1, 0]]  # -1: a value the run has not seen
    decoded = classes.decode(encoded)
    assert decoded[0, :3].tolist() == [-100.0, 0.0, -1.0] and np.isnan(decoded[0, 3])
    with pytest.raises(ValueError, match="run 1 saw more than 3 distinct reward values; raise max_classes"):
        classes.observe(1, np.array([1.0, 2.0, 3.0]))


def test_while_every_label_is_0_a_goal_reward_is_a_value_no_label_has_shown():
    # No goal step among the labels: the one class (0) cannot stand for a goal reward, so the metrics
    # count a goal step given 0 as wrong, not as right.
    classes = QuantileRewardClasses(2)
    classes.fit(np.zeros(12))
    np.testing.assert_array_equal(classes.encode(np.array([0.0, 0.93, -0.5])), [0, -1, -1])
    result = RoundResult(
        pseudo_class=np.array([[0, 0, 0]]),
        pseudo_weight=np.ones((1, 3)),
        view_weight=np.ones((1, 1, 3)),
        view_class=np.zeros((1, 1, 3), int),
        threshold=np.ones((1, 1, 2)),
        classifier_loss=np.zeros((1, 1)),
        pace=np.ones(1),
        changed=np.ones(1, bool),
        stopped=np.zeros(1, bool),
    )
    stats = round_stats(result.of_run(0), np.ones(3, bool), classes.encode(np.array([0.0, 0.0, 0.93])))
    assert stats["pseudo_accuracy"] == pytest.approx(2 / 3) and stats["worst_class_recall"] == 0.0
    classes.fit(np.array([0.0] * 11 + [0.9]))  # a goal label: its class takes every goal reward
    np.testing.assert_array_equal(classes.encode(np.array([0.0, 0.93])), [0, 1])


def test_the_step_class_keeps_the_steps_reward_apart_from_a_late_goals():
    # DoorKey's labels in round 3 of a 5-label run (seed 200 of the views study): a goal at 0.4456 (a
    # late one), a time-out at 0 (its episode cut, not ended: it went on), goals at 0.9928 and 0.9964.
    rewards = np.array([0.4456, 0.0, 0.9928, 0.9964])
    going_on = np.array([False, True, False, False])
    classes = QuantileRewardClasses(2)
    classes.fit(rewards)  # quantiles alone: the median 0.7192 splits the late goal from the others
    np.testing.assert_allclose(classes.values, [0.2228, 0.9946])  # every step is paid 0.2228
    classes.fit(rewards, going_on)
    np.testing.assert_allclose(classes.values, [0.0, (0.4456 + 0.9928 + 0.9964) / 3])
    np.testing.assert_array_equal(classes.encode(np.array([0.0, 0.4456, 0.9964])), [0, 1, 1])
    # A hidden goal paid 0.3 sits nearer the goals' least label than 0: the goal's class.
    np.testing.assert_array_equal(classes.encode_hidden(np.array([0.0, 0.3, 0.2])), [0, 1, 0])
    # A step reward above every outcome (0 a step, a crash ending at -1 or -0.5) keeps the top bin.
    classes.fit(np.array([-1.0, 0.0, -0.5, 0.0]), np.array([False, True, False, True]))
    np.testing.assert_allclose(classes.values, [-0.75, 0.0])
    # Steps that went on paying two values, or one lying between the outcomes: quantiles as before.
    for going in ([True, True, False, False], [False, True, False, False]):
        step = QuantileRewardClasses(2)
        step.fit(np.array([0.5, 0.0, -1.0, 1.0]), np.array(going))
        plain = QuantileRewardClasses(2)
        plain.fit(np.array([0.5, 0.0, -1.0, 1.0]))
        np.testing.assert_array_equal(step.values, plain.values)


def test_one_runs_reward_classes_are_a_batch_of_runs_without_the_runs_axis():
    one, batch = RunRewardClasses(3), RewardClasses(1, 3)
    for labels in (np.array([-1.0, -100.0, -1.0]), np.array([0.0, -100.0])):
        one.observe(labels)
        batch.observe(0, labels)
    assert one.values.tolist() == batch.values[0].tolist() == [-1.0, -100.0, 0.0]
    rewards = np.array([-100.0, 0.0, 5.0])
    assert one.encode(rewards).tolist() == batch.encode(rewards[None])[0].tolist() == [1, 2, -1]
    assert one.decode(np.array([2, -1]))[0] == 0.0 and np.isnan(one.decode(np.array([-1]))[0])
    assert one.mask.tolist() == [True, True, True]
    with pytest.raises(ValueError, match="the run saw more than 3 distinct reward values"):
        one.observe(np.array([7.0]))


def test_round_stats_read_the_run_they_are_given_in_a_batch():
    # Two runs of one view, four samples; run 1 admits samples 1-3 and gets sample 3 wrong.
    result = RoundResult(
        pseudo_class=np.array([[0, 1, -1, -1], [-1, 1, 0, 0]]),
        pseudo_weight=np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 1.0, 0.5, 0.5]]),
        view_weight=np.array([[[1.0, 1.0, 0.0, 0.0], [0.0, 1.0, 0.5, 0.5]]]),
        view_class=np.array([[[0, 1, 0, 0], [0, 1, 0, 0]]]),
        threshold=np.array([[[0.2, 0.4], [0.6, np.nan]]]),
        classifier_loss=np.array([[0.3, 0.7]]),
        pace=np.array([0.5, 0.75]),
        changed=np.ones(2, bool),
        stopped=np.array([False, True]),
    )
    truth = np.array([0, 1, 0, 1])
    unlabelled = np.array([False, True, True, True])
    stats = round_stats(result.of_run(1), unlabelled, truth)
    assert stats["pace"] == 0.75 and stats["stopped"] is True
    assert stats["coverage"] == 1.0  # samples 1-3 of U, all admitted
    assert stats["pseudo_accuracy"] == pytest.approx(2 / 3)  # sample 3: class 0, truly 1
    assert stats["worst_class_recall"] == 0.5  # class 1: samples 1 (right) and 3 (wrong)
    assert stats["worst_class_precision"] == 0.5  # given 0: samples 2 (right) and 3 (wrong)
    view = stats["views"][0]
    assert view["view_coverage"] == 1.0 and view["view_pseudo_accuracy"] == pytest.approx(2 / 3)
    assert view["lambda"] == 0.6 and view["classifier_loss"] == 0.7
    assert view["view_error"] == pytest.approx(1 / 3)  # sample 3 of U, predicted 0 and truly 1
    first = round_stats(result.of_run(0), unlabelled, truth)
    assert first["coverage"] == pytest.approx(1 / 3) and first["pseudo_accuracy"] == 1.0
    assert first["stopped"] is False and first["views"][0]["lambda"] == pytest.approx(0.3)


def test_error_dependence_by_hand():
    # Eight samples of U, all of class 0 but the last, a value no label showed: left out, since every
    # predictor errs on it.
    truth = np.array([0, 0, 0, 0, 0, 0, 0, -1])
    where = np.ones(8, bool)
    # A predicts class 1 on samples 0-3, B on 2-5: of the seven scored, each errs on 4, both on 2 and 3.
    a = np.array([1, 1, 1, 1, 0, 0, 0, 0])
    b = np.array([0, 0, 1, 1, 1, 1, 0, 0])
    stats = error_dependence(np.stack([a, b]), truth, where)
    assert stats["joint_error"] == pytest.approx(2 / 7)
    assert stats["independent_error"] == pytest.approx(16 / 49)
    assert stats["disagreement"] == pytest.approx(4 / 7)  # samples 0, 1, 4, 5
    assert stats["error_correlation"] == pytest.approx((2 / 7 - 16 / 49) / (4 / 7 * 3 / 7))  # -1/6
    # Errors on the same samples correlate 1; identical predictors never disagree.
    same = error_dependence(np.stack([a, a]), truth, where)
    assert same["error_correlation"] == pytest.approx(1.0) and same["disagreement"] == 0.0
    # Only the samples of ``where`` count: of 2, 3, 4 and 6, both err on 2 and 3.
    assert (
        error_dependence(np.stack([a, b]), truth, np.isin(np.arange(8), [2, 3, 4, 6, 7]))["joint_error"]
        == 0.5
    )
    # One predictor, or no sample scored (the unseen value alone), gives NaN.
    assert all(np.isnan(v) for v in error_dependence(a[None], truth, where).values())
    assert np.isnan(error_dependence(np.stack([a, b]), truth, np.arange(8) == 7)["disagreement"])
    # A predictor never wrong has no error correlation, while its joint error is still 0.
    right = error_dependence(np.stack([np.zeros(8, int), b]), truth, where)
    assert np.isnan(right["error_correlation"]) and right["joint_error"] == 0.0


def test_round_stats_compare_the_members_where_the_round_names_them():
    # One view (no pair of views), three ensemble members: the dependence figures read the members.
    n = 4
    result = RunRound(
        pseudo_class=np.zeros(n, int),
        pseudo_weight=np.ones(n),
        view_weight=np.ones((1, n)),
        view_class=np.zeros((1, n), int),
        threshold=np.full((1, 2), np.nan),
        classifier_loss=np.zeros(1),
        pace=1.0,
        changed=1.0,
        stopped=False,
        member_class=np.array([[0, 0, 1, 1], [0, 1, 1, 0], [0, 0, 0, 0]]),
    )
    stats = round_stats(result, np.ones(n, bool), np.zeros(n, int))
    assert stats["disagreement"] == 0.75 and stats["joint_error"] == 0.0
    assert stats["independent_error"] == 0.0  # the third member is never wrong
    assert stats["views"][0]["view_error"] == 0.0
    views_only = round_stats(replace(result, member_class=None), np.ones(n, bool), np.zeros(n, int))
    assert np.isnan(views_only["disagreement"])  # one view: no pair to compare


def test_record_head_names_the_run_and_the_agent():
    head = ("dospcot", ("esarsa", "q"), ("coords", "patch"), 0.3, 4)
    assert record_head(*head, 2, np.int64(1)) == {
        "method": "dospcot",
        "agents": "esarsa-q",
        "views": "coords-patch",
        "m": 2,
        "gamma": 0.3,
        "seed": 4,
        "round": 2,
        "agent": 1,
        "kind": "q",
        "view": "patch",
    }
    assert type(record_head(*head, 2, np.int64(1))["agent"]) is int


def test_a_class_labelled_only_on_episode_ends_is_open_only_to_episode_ends():
    # Classes: 0 (labelled on a step that goes on and on an end: open everywhere), 1 (labelled only on
    # ends: a goal), 2 (labelled only on steps that go on), 3 (the run has none yet).
    label_class = np.array([0, 0, 1, 2, -1, -1, 9])
    labelled = np.array([True, True, True, True, False, False, False])
    terminal = np.array([False, True, True, False, False, True, False])
    class_mask = np.array([True, True, True, False])
    mask = episode_end_class_mask(label_class, labelled, terminal, class_mask)
    expected_on = [True, True, True, False]  # an episode end may take any class the run has
    expected_off = [True, False, True, False]  # a step that goes on may not take the goal class
    np.testing.assert_array_equal(mask, [expected_on if t else expected_off for t in terminal])
    # Every class the run has is shown only on ends: a step that goes on keeps them all.
    only_ends = episode_end_class_mask(
        np.array([1, 0]), np.array([True, False]), np.array([True, False]), np.array([False, True])
    )
    np.testing.assert_array_equal(only_ends, [[False, True], [False, True]])


def test_a_class_a_sample_may_not_take_is_never_its_pseudo_label():
    # One view whose classifier separates the labels cleanly; sample 3 looks like class 1, but its mask
    # forbids class 1, so it is given class 0 or nothing, never 1.
    x = np.array([[[0.0], [1.0], [0.1], [0.9], [0.95]]])
    labelled = np.array([[True, True, False, False, False]])
    label_class = np.array([[0, 1, -1, -1, -1]])
    mask = np.ones((1, 5, 2), bool)
    mask[0, 3, 1] = False
    trainer = SelfPacedCoTrainer([1], 1, CoTrainingConfig(add_fraction_start=1.0, max_classes=2), [0], 2)
    result = trainer.step(Pool([x], labelled, label_class, ~labelled, mask))
    assert result.pseudo_class[0, 4] == 1 and result.pseudo_class[0, 2] == 0
    assert result.pseudo_class[0, 3] != 1 and result.view_class[0, 0, 3] != 1


def test_key_features_by_hand():
    views = np.array([[1.0, 0.0], [0.0, 2.0], [3.0, 3.0]], dtype=np.float32)  # 3 states, d = 2
    next_state = np.array([[1, 0, 2, 2, 0, 1]])  # 3 states x 2 actions, one run
    visited = np.array([[True, False, True, False, False, True]])
    x = key_features(views, next_state, visited, n_actions=2)
    assert x.shape == (1, 6, 2 * 2 + 2) and x.dtype == np.float32
    # Key k = s * A + a: view of s, one-hot a, view of the stored s' (zeros while unseen).
    assert x[0, 0].tolist() == [1, 0, 1, 0, 0, 2]  # s0, a0 -> s1
    assert x[0, 1].tolist() == [1, 0, 0, 1, 0, 0]  # s0, a1, unseen
    assert x[0, 2].tolist() == [0, 2, 1, 0, 3, 3]  # s1, a0 -> s2
    assert x[0, 5].tolist() == [3, 3, 0, 1, 0, 2]  # s2, a1 -> s1


def _separable_pool(n_views: int) -> tuple[Pool, np.ndarray]:
    """40 samples of two classes (20 each) that every view tells apart; 2 labels per class."""
    truth = np.repeat([0, 1], 20)
    labelled = np.zeros(40, dtype=bool)
    labelled[[0, 1, 20, 21]] = True
    onehot = np.eye(2)[truth]
    features = [np.concatenate([onehot, np.full((40, j), 0.5)], axis=1)[None] for j in range(n_views)]
    pool = Pool(
        features,
        labelled[None],
        np.where(labelled, truth, -1)[None],
        ~labelled[None],
        np.array([[True, True]]),
    )
    return pool, truth


@pytest.mark.parametrize("n_views", [1, 2])
def test_the_self_paced_schedule_admits_per_class_quotas_then_everything(n_views):
    pool, truth = _separable_pool(n_views)
    config = CoTrainingConfig(
        max_classes=2, add_fraction_start=0.5, add_fraction_step=0.5, stop_when_fully_admitted=True
    )
    trainer = SelfPacedCoTrainer([f.shape[2] for f in pool.features], 1, config, [0], config.max_classes)
    first = trainer.step(pool)
    # add_num = 0.5 * |U| = 18; each class holds half the labels, so 9 of each are admitted.
    admitted = first.pseudo_weight[0] > 0
    assert admitted.sum() == 18 and admitted[truth == 0].sum() == admitted[truth == 1].sum() == 9
    assert not admitted[pool.labelled[0]].any() and (first.pseudo_class[0][pool.labelled[0]] == -1).all()
    assert (first.pseudo_class[0][admitted] == truth[admitted]).all()
    assert (first.pseudo_class[0][~admitted] == -1).all()
    assert first.pace[0] == pytest.approx(0.5) and first.changed[0] == 1.0 and not first.stopped[0]
    assert first.view_weight.shape == (n_views, 1, 40) and first.threshold.shape == (n_views, 1, 2)
    second = trainer.step(pool)
    # add_num = 1.0 * |U|: all 36 unlabelled samples, each with its true class; the rule stops.
    assert second.pace[0] == 1.0 and second.stopped[0]
    assert (second.pseudo_class[0][~pool.labelled[0]] == truth[~pool.labelled[0]]).all()
    assert second.changed[0] == pytest.approx(18 / 36)  # the 18 newly admitted samples changed


def test_candidate_quotas_admit_a_rare_class_whose_labels_understate_it():
    # 30 samples of class 0 and 10 of class 1; the labels hold 4 of class 0 and 1 of class 1 (a
    # share of 0.2 against the pool's 0.25).
    truth = np.repeat([0, 1], [30, 10])
    labelled = np.zeros(40, dtype=bool)
    labelled[[0, 1, 2, 3, 30]] = True
    pool = Pool(
        [np.eye(2)[truth][None]],
        labelled[None],
        np.where(labelled, truth, -1)[None],
        ~labelled[None],
        np.array([[True, True]]),
    )
    for quota, rare_admitted in (("label-share", 7), ("candidates", 9)):
        config = CoTrainingConfig(max_classes=2, add_fraction_start=1.0, quota=quota)
        result = SelfPacedCoTrainer([2], 1, config, [0], config.max_classes).step(pool)
        admitted = result.pseudo_weight[0] > 0
        # add_num = |U| = 35. Label share: class 1 gets ceil(0.2 * 35) = 7 of its 9 candidates.
        # Candidates: every class admits all its candidates (26 and 9).
        assert admitted[truth == 1].sum() == rare_admitted
        assert admitted[truth == 0].sum() == 26


def test_the_single_run_cotrainer_is_the_batched_one_on_a_batch_of_one():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(12, 3))
    labelled = np.arange(12) < 4
    label_class = np.where(labelled, np.arange(12) % 2, -1)
    mask = np.array([True, True, False])
    config = CoTrainingConfig(max_classes=3)
    single = RunCoTrainer([3, 3], config, 5, 3)
    batched = SelfPacedCoTrainer([3, 3], 1, config, [5], 3)
    for _ in range(2):  # a second round reads the first one's weights
        one = single.step(RunPool([x, -x], labelled, label_class, ~labelled, mask))
        pool = Pool([x[None], -x[None]], labelled[None], label_class[None], ~labelled[None], mask[None])
        many = batched.step(pool).of_run(0)
        for name in ("pseudo_class", "pseudo_weight", "view_weight", "view_class", "threshold"):
            np.testing.assert_array_equal(getattr(one, name), getattr(many, name))
        assert one.pseudo_class.shape == (12,) and one.view_class.shape == (2, 12)
        assert (one.pace, one.changed, one.stopped) == (many.pace, many.changed, many.stopped)


def test_a_fit_on_the_weighted_samples_alone_is_the_fit_on_the_whole_pool():
    import torch

    from dospcot.core.classifier import BatchedRewardClassifier, ClassifierConfig
    from dospcot.core.self_paced import Numerics, _fit

    rng = np.random.default_rng(1)
    x = torch.from_numpy(rng.normal(size=(1, 50, 4)))
    y = torch.from_numpy(rng.integers(0, 2, size=(1, 50)))
    weight = torch.from_numpy((rng.random((1, 50)) > 0.4).astype(np.float64))
    mask = torch.ones(1, 50, 2, dtype=torch.bool)  # per sample, as episode-end classes give
    fits = []
    for weighted_only in (False, True):
        clf = BatchedRewardClassifier(1, 4, 2, ClassifierConfig(epochs=60), [3])
        loss = _fit(clf, Numerics(torch.float64, weighted_only), x, y, weight, mask)
        fits.append((loss, list(clf.parameters())))
    (loss_all, all_params), (loss_weighted, weighted_params) = fits
    torch.testing.assert_close(loss_all, loss_weighted, rtol=1e-12, atol=1e-12)
    for p, q in zip(all_params, weighted_params, strict=True):
        torch.testing.assert_close(p, q, rtol=1e-9, atol=1e-12)


def test_a_weighted_fit_whose_every_sample_carries_weight_reads_the_pool_itself_bit_for_bit():
    import torch

    from dospcot.core.classifier import BatchedRewardClassifier, ClassifierConfig
    from dospcot.core.self_paced import NUMERICS, _fit

    rng = np.random.default_rng(2)
    x = torch.from_numpy(rng.normal(size=(1, 40, 4)).astype(np.float32))
    y = torch.from_numpy(rng.integers(0, 2, size=(1, 40)))
    weight = torch.from_numpy(rng.uniform(0.1, 1.0, size=(1, 40)).astype(np.float32))
    mask = torch.ones(1, 2, dtype=torch.bool)
    read = []

    def fitted(pool: torch.Tensor, weight: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        clf = BatchedRewardClassifier(1, 4, 2, ClassifierConfig(epochs=40), [3]).to(torch.float32)
        fit = clf.fit
        clf.fit = lambda features, *rest: read.append(features) or fit(features, *rest)
        return _fit(clf, NUMERICS[2], pool, y, weight, mask), [p.detach() for p in clf.parameters()]

    (loss, params), (copy_loss, copy_params) = fitted(x, weight), fitted(x.clone(), weight)
    assert read[0] is x  # the pool itself, where a subset of every sample was a copy of it
    assert torch.equal(loss, copy_loss)
    assert all(torch.equal(p, q) for p, q in zip(params, copy_params, strict=True))
    weight[0, 5] = 0.0  # a sample without weight: the fit reads the others alone
    fitted(x, weight)
    assert read[-1].shape == (1, 39, 4)


def test_numerics_2_fits_in_float32_and_a_config_pickled_before_the_key_reads_as_1():
    import dataclasses
    import pickle

    import torch

    pool, _ = _separable_pool(2)
    config = CoTrainingConfig(max_classes=2)
    dims = [f.shape[2] for f in pool.features]
    new = SelfPacedCoTrainer(dims, 1, dataclasses.replace(config, numerics=2), [0], 2)
    assert all(p.dtype == torch.float32 for clf in new.classifiers for p in clf.parameters())
    new.step(pool)
    old = SelfPacedCoTrainer(dims, 1, config, [0], 2)
    assert old.numerics == 1 and old.dtype == torch.float64
    del old.config.__dict__["numerics"]  # as a checkpoint written before the key holds its config
    loaded = pickle.loads(pickle.dumps(old))
    assert loaded.numerics == 1 and loaded.dtype == torch.float64
    loaded.step(pool)
    assert RunCoTrainer([3], config, 0, 2).numerics == 1  # the default until the same-science check
    with pytest.raises(ValueError, match="numerics must be one of 1, 2, 3, got 7"):
        CoTrainingConfig(numerics=7)


@pytest.mark.parametrize("numerics", [2, 3])
def test_run_info_names_the_numerics_version_runs_are_trained_with(tmp_path, numerics):
    from dospcot.run.run_session import RunSession
    from dospcot.run.sb3_runs import build_run
    from dospcot.tasks import load_config

    cfg = load_config(
        "tiny", ["training.rounds=1", "training.steps_per_round=200", f"cotraining.numerics={numerics}"]
    )
    run = build_run(cfg)
    assert run.trainer.numerics == numerics
    assert [agent.fused_adam for agent in run.agents] == [numerics == 3] * len(run.agents)
    (tmp_path / "config.toml").write_text("")
    session = RunSession(tmp_path, cfg, None, "dospcot train tiny")
    session.run.run(on_round=lambda run, rows: session.after_round(rows))
    session.finish()
    assert json.loads((tmp_path / "run_info.json").read_text())["numerics"] == numerics


def test_a_finished_session_drops_its_replay_buffers_before_it_loads_the_plotting_stack(
    tmp_path, monkeypatch
):
    """The buffers, saved with no agent, are what a run holds most of: gone before matplotlib loads."""
    from dospcot.run import plots
    from dospcot.run.run_session import RunSession
    from dospcot.tasks import load_config

    cfg = load_config("tiny", ["training.rounds=1", "training.steps_per_round=200"])
    (tmp_path / "config.toml").write_text("")
    session = RunSession(tmp_path, cfg, None, "dospcot train tiny")
    session.run.run(on_round=lambda run, rows: session.after_round(rows))
    assert all(agent.replay_buffer.size() == 200 for agent in session.run.agents)
    held, plot = [], plots.plot_learning_curves

    def plot_and_note(*args, **kwargs) -> None:
        held.append([agent.replay_buffer for agent in session.run.agents])
        plot(*args, **kwargs)

    monkeypatch.setattr(plots, "plot_learning_curves", plot_and_note)
    session.finish()
    assert held == [[None] * len(cfg.views)]
    assert (tmp_path / "learning_curves.png").stat().st_size > 0
    assert json.loads((tmp_path / "summary.json").read_text())["rounds"] == 1


def _late_class_pool(late_class: bool) -> tuple[Pool, np.ndarray]:
    """60 samples: 50 of class 0 (features [1, 0]), 10 of class 1 ([0, 1]); 6 class-0 labels, and with
    ``late_class`` one label of class 1 too (before it, the run has seen class 0 alone)."""
    truth = np.repeat([0, 1], [50, 10])
    labelled = np.zeros(60, dtype=bool)
    labelled[:6] = True
    labelled[50] = late_class
    features = np.eye(2)[truth][None]
    label_class = np.where(labelled, truth, -1)[None]
    return Pool(
        [features, features], labelled[None], label_class, ~labelled[None], np.ones((1, 2), bool)
    ), truth


def _class_after_it_appears(refit: bool, seed: int) -> np.ndarray:
    """Round 1 labels class 0 alone; round 2 labels one sample of class 1: the pseudo-classes round 2
    gives the unlabelled samples."""
    config = CoTrainingConfig(max_classes=2, add_fraction_start=1.0, refit_new_classes=refit)
    trainer = SelfPacedCoTrainer([2, 2], 1, config, [seed], 2)
    trainer.step(_late_class_pool(False)[0])
    pool, _ = _late_class_pool(True)
    return trainer.step(pool).pseudo_class[0][pool.unlabelled[0]]


def test_a_class_first_labelled_after_round_1_is_learnt_from_the_labels_before_it_is_given():
    pool, truth = _late_class_pool(True)
    truth = truth[pool.unlabelled[0]]
    for seed in range(4):
        refit = _class_after_it_appears(True, seed)
        # Refit on the labels, the views tell the classes apart: every unlabelled sample is admitted
        # with its own class, the new one's nine included.
        assert (refit == truth).all()
        # Without it, class 1's output was never trained (rounds before masked it), the carried
        # weights hold every sample at class 0, and the new class is given to none of its samples:
        # the lava class's recall of 0 on grid16 in issue 58's sixth exploration.
        old = _class_after_it_appears(False, seed)
        assert (old[truth == 1] != 1).all()


def test_a_co_trainer_restored_between_rounds_still_refits_on_a_class_it_had_not_seen():
    import pickle

    config = CoTrainingConfig(max_classes=2, add_fraction_start=1.0, refit_new_classes=True)
    kept = SelfPacedCoTrainer([2, 2], 1, config, [0], 2)
    kept.step(_late_class_pool(False)[0])
    # A checkpoint between the rounds carries which classes the labels have shown, so the restored
    # co-trainer knows class 1 is new in round 2 (without it, it would take class 1 as seen before).
    restored = pickle.loads(pickle.dumps(kept))
    pool, truth = _late_class_pool(True)
    ours, theirs = restored.step(pool), kept.step(pool)
    np.testing.assert_array_equal(ours.pseudo_class, theirs.pseudo_class)
    np.testing.assert_array_equal(ours.view_weight, theirs.view_weight)
    assert (ours.pseudo_class[0][pool.unlabelled[0]] == truth[pool.unlabelled[0]]).all()


def _stack(a: Pool, b: Pool) -> Pool:
    """Two one-run pools as a batch of two runs."""
    return Pool(
        [np.concatenate([f, g]) for f, g in zip(a.features, b.features, strict=True)],
        *(
            np.concatenate([getattr(a, k), getattr(b, k)])
            for k in ("labelled", "label_class", "unlabelled", "class_mask")
        ),
    )


def test_a_refit_for_one_runs_new_class_leaves_the_other_runs_of_a_batch_as_they_would_be_alone():
    config = CoTrainingConfig(max_classes=2, add_fraction_start=0.5, refit_new_classes=True)
    first, _ = _late_class_pool(False)
    second, _ = _late_class_pool(True)
    batch = SelfPacedCoTrainer([2, 2], 2, config, [0, 1], 2)
    batch.step(_stack(first, first))
    both = batch.step(_stack(second, first))  # run 0 sees class 1 now, run 1 does not
    alone = SelfPacedCoTrainer([2, 2], 1, config, [1], 2)
    alone.step(first)
    one = alone.step(first)
    np.testing.assert_array_equal(both.pseudo_class[1], one.pseudo_class[0])
    np.testing.assert_array_equal(both.view_weight[:, 1], one.view_weight[:, 0])
