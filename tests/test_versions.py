"""Versions of the defaults (dospcot/config/versions.py): a config without ``defaults`` gets the adopted
version, a key the config sets keeps its value under any version, a run folder written before versions
existed reads as version 1, and ``dospcot config`` names each moved default's first value."""

from __future__ import annotations

import dataclasses

import pytest
import tomli_w

from dospcot.cli import main
from dospcot.config.errors import ConfigError
from dospcot.config.presets import preset_names
from dospcot.config.reference import config_reference
from dospcot.config.version_defaults import gym_moves, lineage, moved_for_some_methods
from dospcot.config.versions import ADOPTED, BUDGET, VERSIONS
from dospcot.tasks import load_config, load_run_config


def _moved(preset: str, *overrides: str) -> tuple:
    cfg = load_config(preset, ["defaults=2", *overrides])
    t = cfg.training
    return (t.exploration, t.agent_draws, t.label_strategy, t.query_schedule, t.label_budget)


def test_a_config_without_the_key_gets_the_adopted_version_and_version_1_is_the_dataclasses():
    assert ADOPTED == 14 and VERSIONS[1] == ()
    for preset in ("grid16-dospcot", "minigrid-doorkey-oracle", "tiny"):
        assert load_config(preset) == load_config(preset, ["defaults=14"])
    # version 14 buys round 1's labels at its first pass for DOSPCoT
    assert load_config("grid16-dospcot").training.first_labels == "first_pass"
    assert load_config("grid16-dospcot", ["defaults=13"]).training.first_labels == "round_end"
    # version 13 keeps the steps' reward class apart where a gym task's method learns rewards
    assert load_config("minigrid-doorkey-dospcot").gym.step_class
    assert not load_config("minigrid-doorkey-dospcot", ["defaults=12"]).gym.step_class
    assert not load_config("minigrid-doorkey-oracle").gym.step_class
    cfg = load_config("grid16-dospcot", ["defaults=3"])
    assert cfg.defaults == 3
    # version 3 is version 1 with numerics 2's fits, and moves nothing else
    first = load_config("grid16-dospcot", ["defaults=1"])
    assert cfg.cotraining.numerics == 2 and first.cotraining.numerics == 1
    numerics_2 = dataclasses.replace(first.cotraining, numerics=2)
    assert dataclasses.replace(first, defaults=3, cotraining=numerics_2) == cfg
    t = cfg.training
    assert (t.exploration, t.agent_draws, t.label_strategy, t.label_budget) == (
        "pace",
        "shared",
        "uniform",
        0,
    )
    assert not cfg.cotraining.refit_new_classes and not cfg.env.episode_end_classes


def test_each_version_builds_on_the_one_it_names_and_the_reference_shows_the_adopted_defaults():
    assert (lineage(1), lineage(2), lineage(3), lineage(4)) == ([], [2], [3], [3, 4])
    # version 4 is version 3 with exploration by rounds, and moves nothing else
    adopted, fourth = (
        load_config("minigrid-doorkey-dospcot", ["defaults=3"]),
        load_config("minigrid-doorkey-dospcot", ["defaults=4"]),
    )
    rounds = dataclasses.replace(adopted.training, exploration="rounds")
    assert dataclasses.replace(adopted, defaults=4, training=rounds) == fourth
    # version 5 is version 3 with four co-training passes a round, for a run that learns single rewards
    fifth = load_config("minigrid-doorkey-dospcot", ["defaults=5"])
    passes = dataclasses.replace(adopted.training, cotrain_passes=4)
    assert dataclasses.replace(adopted, defaults=5, training=passes) == fifth
    assert load_config("minigrid-doorkey-oracle", ["defaults=5"]).training.cotrain_passes == 1
    assert load_config("tiny", ["defaults=5", "training.steps_per_round=3"]).training.cotrain_passes == 3
    assert load_config("tiny", ["defaults=5", "training.segment_length=4"]).training.cotrain_passes == 1
    for bad in ("training.steps_per_round=nan", "training.steps_per_round=[2]", "training=3"):
        with pytest.raises(ConfigError):  # the config's own check, not the version's rule, answers
            load_config("tiny", ["defaults=5", bad])
    # version 6 is version 5 with the refit on a new class
    refit = dataclasses.replace(fifth.cotraining, refit_new_classes=True)
    sixth = load_config("minigrid-doorkey-dospcot", ["defaults=6"])
    assert dataclasses.replace(fifth, defaults=6, cotraining=refit) == sixth
    # version 7 is version 6 with the passes from round 2, for a run that learns single rewards
    later = dataclasses.replace(sixth.training, passes_from_round=2)
    seventh = load_config("minigrid-doorkey-dospcot", ["defaults=7"])
    assert dataclasses.replace(sixth, defaults=7, training=later) == seventh
    assert load_config("minigrid-doorkey-oracle", ["defaults=7"]).training.passes_from_round == 1
    assert load_config("tiny", ["defaults=7", "training.segment_length=4"]).training.passes_from_round == 1
    # version 8 is version 7 with exploration by rounds, for every method
    rounds = dataclasses.replace(seventh.training, exploration="rounds")
    eighth = load_config("minigrid-doorkey-dospcot", ["defaults=8"])
    assert dataclasses.replace(seventh, defaults=8, training=rounds) == eighth
    assert load_config("minigrid-doorkey-oracle", ["defaults=8"]).training.exploration == "rounds"
    # version 9 is version 3 with the MiniGrid presets' agents and exploring starts on a gym task
    untuned = "lab/studies/untuned/distshift-oracle.toml"
    third, ninth = load_config(untuned, ["defaults=3"]), load_config(untuned, ["defaults=9"])
    agents = dataclasses.replace(third.dqn, gamma=0.9, n_steps=3, train_freq=2, target_update_interval=250)
    starts = dataclasses.replace(third.gym, train_wrappers=("dospcot.envs.minigrid_views:ReachableStart",))
    eps = dataclasses.replace(third.training, eps_start=0.5, steps_per_round=10_000)
    assert dataclasses.replace(third, defaults=9, dqn=agents, gym=starts, training=eps) == ninth
    cartpole = load_config(
        untuned, ["defaults=9", 'gym.env_id="CartPole-v1"', 'gym.views={obs="observation"}', 'views=["obs"]']
    )
    assert cartpole.gym.train_wrappers == () and cartpole.dqn.gamma == 0.9
    assert load_config(untuned, ["defaults=9", "dqn.gamma=0.99"]).dqn.gamma == 0.99
    # version 10 is version 9 with version 2's queries; its classifiers fit in numerics 2, as version 3's
    co_trained = untuned.replace("-oracle", "")
    second, tenth = load_config(co_trained, ["defaults=2"]), load_config(co_trained, ["defaults=10"])
    queries = dataclasses.replace(second.training, eps_start=0.5, steps_per_round=10_000)
    ninth = load_config(co_trained, ["defaults=9"])
    expected = dataclasses.replace(
        second,
        defaults=10,
        dqn=ninth.dqn,
        gym=dataclasses.replace(ninth.gym, episode_end_classes=True),
        training=queries,
        cotraining=dataclasses.replace(second.cotraining, numerics=2),
    )
    assert tenth == expected
    # version 11 is version 10 with four co-training passes a round from round 2
    passes = dataclasses.replace(tenth.training, cotrain_passes=4, passes_from_round=2)
    eleventh = load_config(co_trained, ["defaults=11"])
    assert eleventh == dataclasses.replace(tenth, defaults=11, training=passes)
    assert load_config(untuned, ["defaults=11"]).training.cotrain_passes == 1  # the oracle co-trains nothing
    # version 12 is version 10 with ten score passes a round, for DOSPCoT alone
    scored = dataclasses.replace(tenth.training, cotrain_passes=10, pass_kind="score")
    twelfth = load_config(co_trained, ["defaults=12"])
    assert twelfth == dataclasses.replace(tenth, defaults=12, training=scored)
    assert load_config(untuned, ["defaults=12"]).training.pass_kind == "cotrain"
    peer = load_config(co_trained, ["defaults=12", 'method="reward-model"', 'views=["image"]'])
    assert (peer.training.cotrain_passes, peer.training.pass_kind) == (1, "cotrain")
    # version 2 builds on version 1, not on the adopted version 3: its classifiers fit in numerics 1
    assert load_config("grid16-dospcot", ["defaults=2"]).cotraining.numerics == 1
    reference = config_reference()
    train, paper = reference.split('## A paper-protocol config (`task = "paper"`)')
    assert "| `numerics` | `int` | `2` (`defaults = 1`: `1`) |" in train
    assert "| `numerics` | `int` | `1` |" in paper and "defaults = 1" not in paper
    # A key moved for some methods only names them, and what the others keep.
    assert moved_for_some_methods()["training.cotrain_passes"] == ["dospcot"]
    assert moved_for_some_methods()["training.label_budget"] == ["dospcot", "reward-model"]
    assert "cotraining.numerics" not in moved_for_some_methods()
    passes = "`10` for method `dospcot` (`defaults = 1`, and the other methods: `1`)"
    assert f"| `cotrain_passes` | `int` | {passes} |" in train
    # A key the adopted version moves for a gym task (a user's own env) names that default too.
    assert '| `steps_per_round` | `int` | `5000`; for a gym task (`task = "gym"`): `10000` |' in train
    learners = '(`task = "gym"`, method `dospcot`, `reward-model`): `true`'
    assert f"| `step_class` | `bool` | `false`; for a gym task {learners} |" in train
    assert gym_moves()["gym.step_class"] == (True, ["dospcot", "reward-model"])


def test_version_2_moves_what_each_method_and_view_count_can_use():
    two_views = ("rounds", "own", "outcomes+disagreement", "decay", BUDGET)
    assert _moved("grid16-dospcot") == two_views
    assert _moved("grid16-self-training") == ("rounds", "own", "outcomes+uncertainty", "decay", BUDGET)
    # The oracle asks no rater: only exploration and draws move.
    assert _moved("grid16-oracle") == ("rounds", "own", "uniform", "asap", 0)
    # A reward model of one view with three members asks where its members disagree.
    assert _moved("grid16-dospcot", 'method="reward-model"', 'views=["coords"]')[2] == "outcomes+disagreement"
    cfg = load_config("grid16-dospcot", ["defaults=2"])
    assert cfg.cotraining.refit_new_classes and cfg.env.episode_end_classes
    assert cfg.training.query_end_states == "spread"
    assert load_config("minigrid-doorkey-dospcot", ["defaults=2"]).gym.episode_end_classes
    # A highway section has no such key, and demonstrations as labels record no episode end.
    assert load_config("fasthighway-dospcot", ["defaults=2"]).training.label_budget == BUDGET
    assert load_config("grid16-dospcot", ["defaults=3"]).training.query_end_states == "random"


def test_a_key_the_config_sets_keeps_its_value_under_version_2():
    assert _moved("grid16-dospcot", 'training.exploration="pace"', "training.label_budget=40")[::4] == (
        "pace",
        40,
    )
    # A preset that sets its strategy keeps it (the fast highway's reward model asks by disagreement).
    assert _moved("fasthighway-reward-model")[2] == "disagreement"


def test_version_2_leaves_the_query_keys_of_a_run_that_asks_no_rater():
    uniform = _moved("grid16-dospcot", 'training.label_strategy="uniform"')
    assert uniform == ("rounds", "own", "uniform", "asap", 0)
    segments = load_config("tiny", ["defaults=2", "training.segment_length=3"]).training
    assert (segments.label_strategy, segments.label_budget) == ("uniform", 0)


def test_version_2s_budget_fits_a_run_too_short_to_meet_it():
    cfg = load_config("tiny", ["defaults=2", "training.rounds=1", "training.steps_per_round=30"])
    assert cfg.training.label_budget == 60 < BUDGET  # 1 round x 30 steps x 2 views
    with pytest.raises(ConfigError, match="label_budget: 500 answers cannot be spent"):
        load_config(
            "tiny",
            ["defaults=2", "training.rounds=1", "training.steps_per_round=30", "training.label_budget=500"],
        )


def test_an_unknown_version_is_one_line_naming_the_versions():
    with pytest.raises(
        ConfigError,
        match=r"^defaults: unknown version 15; the versions: 1, 2 \(candidate\), 3, "
        r"4 \(candidate\), 5 \(candidate\), 6 \(candidate\), 7 \(candidate\), 8 \(candidate\), "
        r"9 \(candidate\), 10 \(candidate\), 11 \(candidate\), 12, 13, 14 \(adopted\)$",
    ):
        load_config("tiny", ["defaults=15"])
    with pytest.raises(ConfigError, match="unknown version True"):
        load_config("tiny", ["defaults=true"])


def test_version_9_trains_every_shipped_preset_as_version_3_does():
    """Version 9 moves only keys a gym task leaves unset, and every preset sets them (or is no gym task)."""
    for preset in preset_names():
        cfg = load_config(preset, ["defaults=3"])
        assert dataclasses.replace(load_config(preset, ["defaults=9"]), defaults=cfg.defaults) == cfg, preset


def test_no_version_moves_a_paper_protocol_key():
    assert load_config("paper-text", ["defaults=2"]).tabular == load_config("paper-text").tabular
    assert load_config("paper-text").tabular.cotraining.numerics == 1


def test_a_run_folder_written_before_versions_reads_as_version_1(tmp_path):
    for preset in ("tiny", "paper-text"):
        old = load_config(preset).to_dict()
        del old["defaults"]
        (tmp_path / "config.toml").write_text(tomli_w.dumps(old))
        assert load_run_config(tmp_path / "config.toml").defaults == 1
    # A folder written under version 2 holds every key: it reads back whatever the adopted version.
    cfg = load_config("tiny", ["defaults=2"])
    (tmp_path / "config.toml").write_text(tomli_w.dumps(cfg.to_dict()))
    assert load_run_config(tmp_path / "config.toml") == cfg


def test_dospcot_config_names_the_version_and_each_moved_defaults_first_value(capsys):
    assert main(["config", "tiny", "--set", "defaults=2"]) == 0
    out = capsys.readouterr().out
    versions = (
        "(the versions: 1, 2 (candidate), 3, 4 (candidate), 5 (candidate), 6 (candidate), "
        "7 (candidate), 8 (candidate), 9 (candidate), 10 (candidate), 11 (candidate), 12, 13, "
        "14 (adopted))"
    )
    assert f"under version 2 of the defaults {versions}" in out.splitlines()[0]
    assert 'exploration = "rounds"  # default "rounds" (defaults = 1: "pace")' in out
    assert "refit_new_classes = true  # default true (defaults = 1: false)" in out
    assert "numerics = 1  # default 1:" in out  # version 2 builds on version 1
    assert main(["config", "tiny"]) == 0
    out = capsys.readouterr().out
    assert f"under version 14 of the defaults {versions}" in out.splitlines()[0]
    assert 'pass_kind = "score"  # default "score" (defaults = 1: "cotrain")' in out
    assert main(["config", "tiny", "--set", "defaults=3"]) == 0
    out = capsys.readouterr().out
    assert f"under version 3 of the defaults {versions}" in out.splitlines()[0]
    assert [line for line in out.splitlines() if "(defaults = 1:" in line] == [
        next(
            line
            for line in out.splitlines()
            if line.startswith("numerics = 2  # default 2 (defaults = 1: 1)")
        )
    ]
    assert main(["config", "tiny", "--set", "defaults=1"]) == 0
    assert "(defaults = 1:" not in capsys.readouterr().out


@pytest.mark.parametrize(
    "bad",
    [
        ["training.segment_length=[2]"],
        ["training=3"],
        ["demonstrations=3"],
        ["views=3"],
        ['method="reward-model"', "cotraining.ensemble_size=[1]"],
    ],
)
@pytest.mark.parametrize("version", [2, 5, 9, 10, 11, 12])
def test_a_versions_rules_leave_a_malformed_value_to_the_configs_own_check(version, bad):
    """A rule reads only the values it can; the config's check then names what is wrong in one line,
    rather than the rule failing with a TypeError of its own."""
    with pytest.raises(ConfigError):
        load_config("tiny", [f"defaults={version}", *bad])


def test_a_share_set_where_the_version_buys_labels_is_refused_with_the_ways_to_a_mask_or_a_budget():
    """Under the adopted version a rater buys 100 labels, so a share set by hand would go unread."""
    with pytest.raises(ConfigError, match=r"^training.label_fraction: unread, since a rater buys"):
        load_config("tiny", ["training.label_fraction=0.5"])
    mask = load_config("tiny", ["training.label_fraction=0.5", 'training.label_strategy="uniform"'])
    assert (mask.training.label_budget, mask.mask_fraction) == (0, 0.5)
    # A budget of the share: the version's decaying schedule needs a budget counted in labels.
    share = load_config("tiny", ["training.label_fraction=0.5", "training.label_budget=0"]).training
    assert (share.label_strategy, share.query_schedule, share.label_budget) == (
        "outcomes+disagreement",
        "asap",
        0,
    )
    # The preset's own share is no one's instruction: tiny sets one, and trains on the version's budget.
    assert load_config("tiny").training.label_budget == BUDGET
    assert load_config("tiny", ["defaults=3", "training.label_fraction=0.5"]).mask_fraction == 0.5


def test_a_run_with_no_view_is_told_so_under_a_version_that_buys_labels():
    with pytest.raises(ConfigError, match="views: need at least one view"):
        load_config("tiny", ["views=[]"])


def test_version_13_keeps_the_steps_class_apart_for_a_gym_task_that_learns_rewards():
    """Version 13 moves ``gym.step_class`` for a gym task whose method learns rewards, and nothing else:
    the oracle and the grid keep version 12's configs."""
    assert load_config("minigrid-doorkey-dospcot", ["defaults=13"]).gym.step_class
    assert not load_config("minigrid-doorkey-dospcot", ["defaults=12"]).gym.step_class
    assert not load_config("minigrid-doorkey-oracle", ["defaults=13"]).gym.step_class
    assert load_config("grid16-dospcot", ["defaults=13"]) == dataclasses.replace(
        load_config("grid16-dospcot", ["defaults=12"]), defaults=13
    )


def test_version_14_buys_round_1s_labels_at_its_first_pass_where_dospcot_has_one():
    """Version 14 moves ``training.first_labels`` for DOSPCoT alone, and only where round 1 comes in
    passes and the rater is simulated (the key's own check refuses it elsewhere); nothing else moves."""
    cfg = load_config("minigrid-doorkey-dospcot", ["defaults=14"])
    assert cfg.training.first_labels == "first_pass"
    before = load_config("minigrid-doorkey-dospcot", ["defaults=13"])
    assert dataclasses.replace(cfg, defaults=13, training=before.training) == before
    assert dataclasses.replace(cfg.training, first_labels="round_end") == before.training
    for preset, sets in [
        ("minigrid-doorkey-oracle", []),
        ("grid16-reward-model", []),
        ("grid16-dospcot", ["training.cotrain_passes=1"]),
        ("grid16-dospcot", ["training.passes_from_round=2"]),
        ("grid16-dospcot", ["training.steps_per_round=1"]),
        ("grid16-dospcot", ['training.rater="file"']),
        ("grid16-dospcot", ["training.segment_length=4"]),
    ]:
        assert load_config(preset, ["defaults=14", *sets]).training.first_labels == "round_end", sets
