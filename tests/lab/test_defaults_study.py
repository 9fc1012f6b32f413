"""The defaults study (lab/studies/defaults.py) on hand-made runs: version 2 is adopted only where every
paired difference on both presets is non-inferior, and its sweeps train each preset under both
versions with nothing else set."""

import json
from pathlib import Path

import numpy as np
import pytest

from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import STUDIES, sweep_spec
from dospcot_lab.studies.declaration import NOT_MEASURED
from dospcot_lab.studies.defaults import TWO_AGAINST_ONE
from dospcot_lab.studies.defaults_4 import FOUR_AGAINST_THREE
from dospcot_lab.studies.defaults_5 import FIVE_AGAINST_THREE
from dospcot_lab.studies.defaults_6 import SIX_AGAINST_THREE
from dospcot_lab.studies.defaults_7 import SEVEN_AGAINST_THREE
from dospcot_lab.studies.defaults_8 import EIGHT_AGAINST_THREE
from dospcot_lab.studies.defaults_12 import TWELVE_AGAINST_THREE
from dospcot_lab.studies.defaults_13 import THIRTEEN_AGAINST_TWELVE
from dospcot_lab.studies.defaults_14 import FOURTEEN_AGAINST_THIRTEEN
from dospcot_lab.studies.tables import ADOPTION_SEEDS

glance, tables = TWO_AGAINST_ONE.glance, TWO_AGAINST_ONE.tables
glance_4, tables_4 = FOUR_AGAINST_THREE.glance, FOUR_AGAINST_THREE.tables


def _run(tmp_path: Path, preset: str, seed: int, version: int, success: float) -> TrialRun:
    run_dir = tmp_path / f"{preset}-{version}-{seed}"
    run_dir.mkdir()
    (run_dir / "run_info.json").write_text(json.dumps({"cpu_time_s": 60.0}))
    summary = {"mean": {"success": success, "pseudo_accuracy": 0.9, "labelled_steps": 100.0 * version}}
    return TrialRun(Trial(preset, preset, {"defaults": str(version)}, seed), summary, [], run_dir)


def test_version_2_is_adopted_only_where_both_presets_are_non_inferior(tmp_path):
    runs = [
        _run(tmp_path, preset, seed, version, 0.8 + 0.05 * (version == 2) * (seed % 2))
        for preset in ("grid16-dospcot", "minigrid-doorkey-dospcot")
        for seed in range(ADOPTION_SEEDS)
        for version in (1, 2)
    ]
    text = "\n".join(tables(runs))
    assert "| `grid16-dospcot` | 2 | 0.825 [" in text and "| 200.0 [200.0, 200.0] | 60 CPU-s | 20 |" in text
    assert text.count("**held**") == 4
    assert glance(runs).verdict == "version 2 non-inferior: adopt it"
    assert glance([r for r in runs if r.trial.config == "grid16-dospcot"]).verdict.startswith(
        "not measured yet"
    )
    # DoorKey's version 2 losing half its successes: the lower end falls far below -0.05
    worse = [
        r for r in runs if not (r.trial.config.startswith("minigrid") and r.trial.params["defaults"] == "2")
    ]
    (tmp_path / "worse").mkdir()
    worse += [
        _run(tmp_path / "worse", "minigrid-doorkey-dospcot", s, 2, 0.8 * (s % 2))
        for s in range(ADOPTION_SEEDS)
    ]
    assert glance(worse).verdict == "version 2 not shown non-inferior: not adopted"
    assert "**not met**" in "\n".join(tables(worse))
    # The same loss on DoorKey's first two seeds alone decides nothing: the rule names 20 pairs.
    begun = [r for r in worse if r.trial.config.startswith("grid16") or r.trial.seed < 2]
    assert glance(begun).verdict.startswith("not measured yet")
    assert glance(begun).headline.startswith("grid16-dospcot success")


def test_the_studys_sweeps_train_each_preset_under_both_versions_and_pin_nothing_else():
    sweeps = STUDIES["defaults"].sweeps
    trials = [t for sweep in sweeps for t in sweep_spec(sweep, 20).trials(check_task=False)]
    assert {(t.config, t.params["defaults"]) for t in trials} == {
        (preset, version) for preset in ("grid16-dospcot", "minigrid-doorkey-dospcot") for version in "12"
    }
    assert sorted({t.seed for t in trials}) == list(range(20))
    first = {t.load_config().defaults for t in trials}
    assert first == {1, 2}


def _run_4(tmp_path: Path, preset: str, seed: int, version: int, success: float) -> TrialRun:
    """A run of the defaults-4 study: version 4's own, or version 3's (a numerics-2 run)."""
    run_dir = tmp_path / f"{preset}-{version}-{seed}"
    run_dir.mkdir()
    (run_dir / "run_info.json").write_text(json.dumps({"cpu_time_s": 60.0}))
    summary = {"mean": {"success": success, "pseudo_accuracy": 0.9, "labelled_steps": 40.0}}
    params = {"defaults": "4"} if version == 4 else {"cotraining.numerics": "2"}
    return TrialRun(Trial(preset, preset, params, seed), summary, [], run_dir)


def test_version_4_is_paired_with_the_numerics_2_runs_and_a_failing_preset_decides_alone(tmp_path):
    grid16 = [
        _run_4(tmp_path, "grid16-dospcot", seed, version, 1.0 - 0.5 * (version == 4 and seed < 4))
        for seed in range(ADOPTION_SEEDS)
        for version in (3, 4)
    ]
    # grid16's version 4 loses half its success on 4 of 20 seeds: -0.1 on average, far below the margin
    assert glance_4(grid16).verdict == "version 4 not shown non-inferior: not adopted"
    assert glance_4(grid16).headline.startswith(
        "grid16-dospcot success, defaults 4 minus 3, paired by seed: -0.100"
    )
    assert "| `grid16-dospcot` | 4 | 0.900 [" in "\n".join(tables_4(grid16))
    # the same on the first 19 seeds decides nothing: the rule names 20 pairs
    assert glance_4([r for r in grid16 if r.trial.seed < 19]).verdict == NOT_MEASURED
    # DoorKey measured and gaining: the headline still names grid16, the preset that decided
    doorkey = [
        _run_4(tmp_path, "minigrid-doorkey-dospcot", seed, version, 0.5 + 0.5 * (version == 4))
        for seed in range(ADOPTION_SEEDS)
        for version in (3, 4)
    ]
    both = glance_4(grid16 + doorkey)
    assert both.verdict == "version 4 not shown non-inferior: not adopted"
    assert both.headline.startswith("grid16-dospcot success, defaults 4 minus 3, paired by seed: -0.100")


def test_version_4_trains_each_preset_under_version_3_with_exploration_by_rounds():
    sweep = STUDIES["defaults-4"].sweeps[0]
    trials = sweep_spec(sweep, 20).trials(check_task=False)
    assert [t.config for t in trials[:: len(trials) // 2]] == ["grid16-dospcot", "minigrid-doorkey-dospcot"]
    cfg = trials[0].load_config()
    assert (cfg.defaults, cfg.training.exploration, cfg.cotraining.numerics) == (4, "rounds", 2)


@pytest.mark.parametrize(
    ("version", "pair", "moved"),
    [
        (5, FIVE_AGAINST_THREE, (4, False, 1, "pace")),  # four co-training passes a round
        (6, SIX_AGAINST_THREE, (4, True, 1, "pace")),  # and the refit on a new class
        (7, SEVEN_AGAINST_THREE, (4, True, 2, "pace")),  # and the passes from round 2
        (8, EIGHT_AGAINST_THREE, (4, True, 2, "rounds")),  # and exploration by rounds
    ],
)
def test_versions_5_to_8_train_each_preset_with_their_moves_and_pair_with_numerics_2(version, pair, moved):
    sweep, numerics_2 = STUDIES[f"defaults-{version}"].sweeps
    assert numerics_2.name == "numerics-2" and STUDIES[f"defaults-{version}"].confirmatory
    trials = sweep_spec(sweep, 20).trials(check_task=False)
    assert [t.config for t in trials[:: len(trials) // 2]] == ["grid16-dospcot", "minigrid-doorkey-dospcot"]
    for trial in trials[:: len(trials) // 2]:
        cfg = trial.load_config()
        assert (cfg.defaults, cfg.cotraining.numerics) == (version, 2)
        training = cfg.training
        moves = (training.cotrain_passes, cfg.cotraining.refit_new_classes, training.passes_from_round)
        assert (*moves, training.exploration) == moved
    runs = [
        TrialRun(Trial("grid16-dospcot", "grid16-dospcot", params, 0), {}, [], Path())
        for params in ({"defaults": str(version)}, {"cotraining.numerics": "2"}, {"defaults": "4"})
    ]
    assert [pair.version_of(run) for run in runs] == [version, 3, None]


def test_version_12_trains_each_preset_with_chosen_labels_and_score_passes_and_pairs_with_numerics_2():
    sweep, numerics_2 = STUDIES["defaults-12"].sweeps
    assert numerics_2.name == "numerics-2" and STUDIES["defaults-12"].confirmatory
    trials = sweep_spec(sweep, 20).trials(check_task=False)
    assert [t.config for t in trials[:: len(trials) // 2]] == ["grid16-dospcot", "minigrid-doorkey-dospcot"]
    for trial in trials[:: len(trials) // 2]:
        cfg = trial.load_config()
        training, cotraining = cfg.training, cfg.cotraining
        assert (cfg.defaults, cotraining.numerics, cotraining.refit_new_classes) == (12, 2, True)
        assert (training.cotrain_passes, training.pass_kind, training.exploration) == (10, "score", "rounds")
        assert (training.label_strategy, training.label_budget) == ("outcomes+disagreement", 100)
    run = TrialRun(Trial("grid16-dospcot", "grid16-dospcot", {"defaults": "12"}, 0), {}, [], Path())
    assert TWELVE_AGAINST_THREE.version_of(run) == 12


def test_a_preset_short_of_its_pairs_is_decided_when_even_its_best_case_fails_the_rule(tmp_path):
    """Version 4 fails outright on two of its first four grid16 seeds: with the other 16 at the most they
    could read (success 1 against version 3's 1), success minus version 3 would read -0.1 on average,
    so the rule fails whatever they show, and the glance says so. Four seeds that lost nothing decide
    nothing."""
    old = [_run_4(tmp_path, "grid16-dospcot", seed, 3, 1.0) for seed in range(ADOPTION_SEEDS)]
    new = [_run_4(tmp_path, "grid16-dospcot", seed, 4, float(seed in (1, 2))) for seed in range(4)]
    pair = FOUR_AGAINST_THREE
    best = pair.best_cases(old + new, "grid16-dospcot")
    assert best["success"].mean == pytest.approx(-2 / ADOPTION_SEEDS) and best["success"].n == ADOPTION_SEEDS
    assert best["pseudo_accuracy"].mean == pytest.approx(0.1 * 16 / ADOPTION_SEEDS)
    assert "grid16-dospcot" in pair.decided_early(old + new, pair.by_preset(old + new))
    row = glance_4(old + new)
    assert row.verdict == "version 4 not shown non-inferior: not adopted"
    assert row.headline.endswith("over 4 seeds (the rule fails whatever the other 16 show)")
    assert any("holds 4 of its 20 pairs, and the rule fails" in line for line in tables_4(old + new))
    (tmp_path / "fine").mkdir()
    fine = [_run_4(tmp_path / "fine", "grid16-dospcot", seed, 4, 1.0) for seed in range(4)]
    assert not pair.decided_early(old + fine, pair.by_preset(old + fine))
    assert glance_4(old + fine).verdict == NOT_MEASURED


def test_version_13_trains_doorkey_first_with_the_step_class_and_pairs_with_version_12s_runs():
    sweep, twelve = STUDIES["defaults-13"].sweeps
    assert twelve.name == "defaults-12" and STUDIES["defaults-13"].confirmatory
    trials = sweep_spec(sweep, 20).trials(check_task=False)
    assert [t.config for t in trials[:: len(trials) // 2]] == ["minigrid-doorkey-dospcot", "grid16-dospcot"]
    doorkey = trials[0].load_config()
    assert (doorkey.defaults, doorkey.gym.step_class, doorkey.training.label_budget) == (13, True, 100)
    runs = [
        TrialRun(Trial("minigrid-doorkey-dospcot", "", {"defaults": version}, 0), {}, [], Path())
        for version in ("13", "12", "3")
    ]
    assert [THIRTEEN_AGAINST_TWELVE.version_of(run) for run in runs] == [13, 12, None]


def test_version_13_on_one_cpu_trains_version_12_again_and_reads_version_13s_runs():
    thirteen, twelve = STUDIES["defaults-13-same-cpu"].sweeps
    assert thirteen == STUDIES["defaults-13"].sweeps[0] and STUDIES["defaults-13-same-cpu"].confirmatory
    trials = sweep_spec(twelve, 20).trials(check_task=False)
    assert [t.config for t in trials[:: len(trials) // 2]] == ["minigrid-doorkey-dospcot", "grid16-dospcot"]
    doorkey = trials[0].load_config()
    assert (twelve.name, doorkey.defaults, doorkey.gym.step_class) == ("defaults-12-same-cpu", 12, False)


def test_the_tables_count_the_pairs_trained_on_one_cpu_model(tmp_path):
    """A pair from two CPU models parts even under one config: the page says how many pairs share one,
    and how many of those took one course (seed 2's version 13 reached the goal sooner; an undefined
    figure, NaN, matches NaN)."""
    runs = []
    for seed in range(3):
        for version in (12, 13):
            run_dir = tmp_path / f"{version}-{seed}"
            run_dir.mkdir()
            cpu = ("Xeon" if (version, seed) == (12, 0) else "EPYC") + ", torch kernels AVX512"
            (run_dir / "run_info.json").write_text(json.dumps({"cpu_time_s": 60.0, "cpu": cpu}))
            returns = -17.0 if (version, seed) == (13, 2) else -19.0
            curves = [{"round": 1.0, "agent": 0.0, "greedy_return": returns, "pseudo_accuracy": np.nan}]
            summary = {"mean": {"success": 1.0, "pseudo_accuracy": 0.9, "labelled_steps": 100.0}}
            trial = Trial("grid16-dospcot", "grid16-dospcot", {"defaults": str(version)}, seed)
            runs.append(TrialRun(trial, summary, curves, run_dir))
    assert THIRTEEN_AGAINST_TWELVE.tables(runs)[-1].startswith(
        "Pairs trained on one CPU model (`run_info.json`'s `cpu`): `grid16-dospcot` 2 of 3 (one course: 1)."
    )


def test_version_14_trains_doorkey_first_with_early_labels_and_pairs_with_version_13s_runs():
    fourteen, thirteen = STUDIES["defaults-14"].sweeps
    assert thirteen == STUDIES["defaults-13"].sweeps[0] and STUDIES["defaults-14"].confirmatory
    trials = sweep_spec(fourteen, 20).trials(check_task=False)
    assert [t.config for t in trials[:: len(trials) // 2]] == ["minigrid-doorkey-dospcot", "grid16-dospcot"]
    doorkey = trials[0].load_config()
    assert (doorkey.defaults, doorkey.training.first_labels, doorkey.gym.step_class) == (
        14,
        "first_pass",
        True,
    )
    runs = [
        TrialRun(Trial("minigrid-doorkey-dospcot", "", {"defaults": version}, 0), {}, [], Path())
        for version in ("14", "13", "12")
    ]
    assert [FOURTEEN_AGAINST_THIRTEEN.version_of(run) for run in runs] == [14, 13, None]
