"""Co-training passes inside a round (``training.cotrain_passes``): the collection in parts, each but the
last followed by a pass of the co-trainer, the self-paced schedule aged per pass."""

from functools import partial

import numpy as np
import pytest
import torch as th
from small_runs import PINNED, grid_config, grid_run

from dospcot.config.errors import ConfigError
from dospcot.config.learning_sections import CoTrainingConfig
from dospcot.core.batched_runs import BatchedRuns, config_refusal
from dospcot.core.sb3_round import collection_parts
from dospcot.core.self_paced import RunCoTrainer, RunPool
from dospcot.envs import GridWorld, grid_views
from dospcot.run.sb3_runs import build_run
from dospcot.tasks import load_config

LAYOUT = GridWorld(size=6, layout_seed=0).layout
SECTIONS = {
    "env": {"max_episode_steps": 36},
    "dqn": {"learning_starts": 50, "buffer_size": 5_000, "net_arch": [32]},
}


def _run(passes: int, seed: int = 3, from_round: int = 1):
    training = {
        "rounds": 2,
        "steps_per_round": 300,
        "label_fraction": 0.2,
        "cotrain_passes": passes,
        "passes_from_round": from_round,
    }
    cfg = grid_config("dospcot", ("dqn", "dqn"), ("coords", "patch"), seed, training=training, **SECTIONS)
    return grid_run(cfg, partial(GridWorld, LAYOUT), grid_views(LAYOUT, patch_size=3))


def test_a_round_is_cut_into_parts_as_equal_as_they_can_be():
    assert collection_parts(10, 3) == [4, 3, 3]
    assert collection_parts(300, 2) == [150, 150] and collection_parts(5, 1) == [5]
    assert all(sum(collection_parts(n, c)) == n for n in (7, 100, 2501) for c in (1, 2, 3, 4, 7))
    # whole multiples of the agents' train_freq, which SB3's learn() collects in full
    assert collection_parts(300, 4, 4) == [76, 76, 76, 72] and collection_parts(302, 4, 4) == [76, 76, 76, 74]
    assert collection_parts(10, 4, 4) == [3, 3, 2, 2]  # fewer units than passes: whole steps


def test_agents_take_the_steps_of_a_round_whatever_their_train_freq():
    """300 steps in four passes with train_freq 4: parts of 76, 76, 76 and 72 steps, so SB3's learn()
    takes no step beyond the round's (75-step parts would each have taken 76)."""
    training = {"rounds": 2, "steps_per_round": 300, "label_fraction": 0.2, "cotrain_passes": 4}
    dqn = {**SECTIONS["dqn"], "train_freq": 4}
    cfg = grid_config(
        "dospcot", ("dqn", "dqn"), ("coords", "patch"), 3, training=training, env=SECTIONS["env"], dqn=dqn
    )
    run = grid_run(cfg, partial(GridWorld, LAYOUT), grid_views(LAYOUT, patch_size=3))
    assert all(r["env_steps"] == 600 for r in run.run()[2:])
    assert run.round_parts() == [76, 76, 76, 72]


def test_each_part_but_the_last_is_followed_by_a_pass_that_writes_the_reward_table():
    """With three passes a round, the co-trainer runs after 100, 200 and 300 steps of every agent; the
    first pass admits samples the agents then learn from while they take the round's next part, and a
    round keeps one set of records however many passes it took."""
    run = _run(3)
    calls = []
    cotrain = run.cotrain

    def spy(record: bool = True) -> dict:
        stats = cotrain(record)
        calls.append(([a.num_timesteps for a in run.agents], record, int((run.table.weight > 0).sum())))
        return stats

    run.cotrain = spy
    records = run.run()
    assert [c[0] for c in calls] == [[100, 100], [200, 200], [300, 300], [400, 400], [500, 500], [600, 600]]
    assert [c[1] for c in calls] == [False, False, True] * 2
    assert calls[0][2] > 0  # admitted after the first part, before the round's end
    assert run.trainer._batch.round == 6
    assert [r["round"] for r in records] == [1, 1, 2, 2] and all(r["env_steps"] == 600 for r in records[2:])
    once = _run(1)
    once.run()
    assert {r["round"] for r in run.class_records} == {1, 2}
    assert len(run.class_records) == len(once.class_records)


def _pool() -> RunPool:
    """40 samples, 8 of them labelled by the sign of their first feature; two views."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 3))
    labelled = np.arange(40) < 8
    label_class = np.where(labelled, (x[:, 0] > 0).astype(np.int64), -1)
    return RunPool([x, -x], labelled, label_class, ~labelled, np.ones(2, bool))


def test_the_schedule_ages_by_one_round_over_a_rounds_passes():
    """Round 1 in one step, round 2 in four: add_num's share grows by add_fraction_step over each round,
    a quarter of it per pass of round 2."""
    config = CoTrainingConfig(add_fraction_start=0.1, add_fraction_step=0.2)
    trainer, pool = RunCoTrainer([3, 3], config, seed=0, n_classes=2), _pool()
    shares = []
    for passes in (1, 4, 4, 4, 4):
        shares.append(trainer._batch.add_fraction)
        trainer.step(pool, passes)
    assert shares == pytest.approx([0.1, 0.3, 0.35, 0.4, 0.45])
    assert trainer._batch.age == 2 and trainer._batch.add_fraction == pytest.approx(0.5)


def test_a_checkpoint_from_before_the_age_reads_its_rounds_from_its_steps():
    """A trainer pickled before the schedule kept its age counted rounds in steps of
    ``passes_per_round`` (1 before that key existed)."""
    trainer = RunCoTrainer([3, 3], CoTrainingConfig(), seed=0, n_classes=2)._batch
    del trainer._age
    trainer.round = 6
    assert trainer.age == 6
    trainer.passes_per_round = 4
    assert trainer.age == 1.5


def test_bad_passes_are_refused_with_the_reason():
    with pytest.raises(ConfigError, match=r"cotrain_passes must lie in \[1, steps_per_round = 300\], got 0"):
        load_config("tiny", ["training.steps_per_round=300", "training.cotrain_passes=0"])
    with pytest.raises(ConfigError, match="got 301"):
        load_config("tiny", ["training.steps_per_round=300", "training.cotrain_passes=301"])
    with pytest.raises(ConfigError, match='method = "oracle" never reads it'):
        load_config("grid16-oracle", ["training.cotrain_passes=2"])
    with pytest.raises(ConfigError, match="segment labels are co-trained once a round"):
        load_config("tiny", ["training.segment_length=4", "training.cotrain_passes=2"])
    assert load_config("tiny", PINNED).training.cotrain_passes == 1


def _batch(seeds: tuple[int, ...]) -> BatchedRuns:
    keys = [*PINNED, "training.rounds=2", "training.steps_per_round=400", "training.cotrain_passes=2"]
    runs = [build_run(load_config("tiny", [*keys, f"seed={seed}"])) for seed in seeds]
    assert config_refusal(runs[0].cfg) is None
    batch = BatchedRuns(runs)
    batch.run()
    return batch


def test_a_batch_of_seeds_takes_its_passes_and_a_member_keeps_its_numbers_beside_another_seed():
    batch, other = _batch((0, 1)), _batch((0, 5))
    assert all(run.trainer._batch.round == 4 for run in batch.runs)
    assert all(agent.num_timesteps == 800 for run in batch.runs for agent in run.agents)
    assert np.array_equal(batch.runs[0].table.reward, other.runs[0].table.reward)
    for a, b in zip(batch.runs[0].agents, other.runs[0].agents, strict=True):
        assert all(th.equal(p, q) for p, q in zip(a.policy.parameters(), b.policy.parameters(), strict=True))


def test_the_stopping_rules_read_a_rounds_last_pass_alone():
    """A pass inside a round neither stops the run nor becomes what the next round's pseudo-labels are
    compared with: ``stop_when_fully_admitted`` fires at the round's end, not at the pass that admitted
    the pool."""
    pool = _pool()
    config = CoTrainingConfig(add_fraction_start=1.0, stop_when_fully_admitted=True)
    trainer = RunCoTrainer([3, 3], config, seed=0, n_classes=2)
    first = trainer.step(pool, 2)
    assert first.pace == 1.0 and not first.stopped and trainer._batch._previous is None
    second = trainer.step(pool, 2)
    assert second.stopped and trainer._batch._previous is not None


def test_passes_from_a_later_round_leave_the_rounds_before_it_one_pass():
    """``passes_from_round = 2``: round 1 collects its 300 steps whole and co-trains once, as without
    passes; round 2 in three passes. The schedule ages by one round each round."""
    run = _run(3, from_round=2)
    steps = []
    cotrain = run.cotrain

    def spy(record: bool = True) -> dict:
        steps.append(run.agents[0].num_timesteps)
        return cotrain(record)

    run.cotrain = spy
    run.run()
    assert steps == [300, 400, 500, 600]
    assert run.trainer._batch.round == 4 and run.trainer._batch.age == 2
    # round 1 is the run without passes, draw for draw
    once = _run(1)
    once.run(until_round=1)
    replay = _run(3, from_round=2)
    replay.run(until_round=1)
    assert np.array_equal(once.table.reward, replay.table.reward)
    assert np.array_equal(once.table.weight, replay.table.weight)
    with pytest.raises(ConfigError, match="passes_from_round must be >= 1, got 0"):
        load_config("tiny", ["training.passes_from_round=0"])
