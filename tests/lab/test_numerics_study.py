"""The numerics versions in the lab: a study's sweeps pin the version they train under, a comparison
that mixes versions is refused, and the numerics study's verdicts on hand-made runs."""

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import pytest

from dospcot.config.learning_sections import CoTrainingConfig
from dospcot.config.loading import renamed_to_now
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import STUDIES, Sweep, study_runs, sweep_spec
from dospcot_lab.studies.defaults import VERSION_SWEEPS
from dospcot_lab.studies.numerics import ADOPT_3, glance, glance_3, tables, tables_3
from dospcot_lab.studies.tables import ADOPTION_SEEDS, numerics_of, paired


def _run(
    tmp_path: Path, preset: str, seed: int, numerics: int | None, success: float, accuracy: float
) -> TrialRun:
    run_dir = tmp_path / f"{preset}-{numerics}-{seed}"
    run_dir.mkdir()
    info = {"cpu_time_s": 100.0 * (numerics or 1)}
    if numerics is not None:  # runs written before the key name no version
        info["numerics"] = numerics
    (run_dir / "run_info.json").write_text(json.dumps(info))
    summary = {"mean": {"success": success, "pseudo_accuracy": accuracy}}
    return TrialRun(Trial(preset, preset, {}, seed), summary, [], run_dir)


@dataclass(frozen=True)
class _Section:
    """A section whose key ``version`` was added after folders were written, at 1, and defaults to 2."""

    added_keys: ClassVar[dict[str, Any]] = {"version": 1}
    version: int = 2
    other: int = 0


@dataclass(frozen=True)
class _Config:
    section: _Section = field(default_factory=_Section)


def test_a_key_added_since_a_folder_was_written_reads_at_the_value_the_folder_ran_under():
    assert renamed_to_now(_Config, {"section": {"other": 3}}) == {"section": {"version": 1, "other": 3}}
    assert renamed_to_now(_Config, {"section": {"version": 2}}) == {"section": {"version": 2}}
    # a checkpoint pickled before cotraining.numerics existed holds a config without it
    state = dict(CoTrainingConfig(numerics=2).__dict__)
    del state["numerics"]
    old = CoTrainingConfig.__new__(CoTrainingConfig)
    old.__setstate__(state)
    assert old.numerics == 1


def test_a_studys_sweep_pins_its_numerics_before_the_commands_overrides():
    assert sweep_spec(Sweep("s", ("tiny",), {}), 2).overrides == ("cotraining.numerics=1",)
    pinned = sweep_spec(Sweep("s", ("tiny",), {}, numerics=2), 2, ["training.rounds=1"])
    assert pinned.overrides == ("cotraining.numerics=2", "training.rounds=1")
    assert pinned.trials()[0].overrides()[0] == "cotraining.numerics=2"
    assert sweep_spec(Sweep("s", ("paper-text",), {}, numerics=None), 2).overrides == ()
    # numerics 2's sweep varies the version in its grid, so it pins nothing; the numerics-1 arms are
    # other studies' sweeps, each pinning the version it trains under
    assert [s.numerics for s in STUDIES["numerics"].sweeps] == [None, 1, 1]


def test_a_comparison_that_mixes_numerics_versions_is_refused(tmp_path):
    old = {s: _run(tmp_path, "grid16-dospcot", s, None, 0.5, 0.9) for s in range(3)}
    new = {s: _run(tmp_path, "grid16-dospcot", s, 2, 1.0, 0.9) for s in range(3)}
    assert numerics_of(old[0]) == 1 and numerics_of(new[0]) == 2
    with pytest.raises(ValueError, match=r"mixes runs of numerics versions \[1, 2\]"):
        paired(new, old, "success")
    diff = paired(new, old, "success", across_numerics=True)
    assert (diff.n, diff.mean) == (3, 0.5)
    assert paired(old, old, "success").mean == 0.0  # one version: compared as before


def test_the_numerics_study_shows_the_registered_bound_and_decides_by_non_inferiority(tmp_path):
    runs = []
    for preset in ("grid16-dospcot", "minigrid-doorkey-dospcot"):
        for seed in range(ADOPTION_SEEDS):
            # the same on every seed but one, where numerics 2 gains 0.1: mean +0.005, within +-0.1
            bump = 0.1 if seed == 0 else 0.0
            runs.append(_run(tmp_path, preset, seed, 1, 0.5, 0.95))
            runs.append(_run(tmp_path, preset, seed, 2, 0.5 + bump, 0.95))
    text = "\n".join(tables(runs))
    assert (
        "| `grid16-dospcot` | 1 | 0.500" in text
        and "| 100 CPU-s | 20 |" in text
        and "| 200 CPU-s | 20 |" in text
    )
    # four lines against the registered equivalence bound, four against the adoption rule
    assert text.count("**held**") == 8 and "not met" not in text
    assert glance(runs).verdict == "numerics 2 non-inferior: adopt it"
    assert glance([r for r in runs if numerics_of(r) == 1]).verdict == "not measured yet"
    # DoorKey without its numerics-1 runs: grid16's difference heads the row, and the row waits for it
    partial_runs = [r for r in runs if not (r.trial.config.startswith("minigrid") and numerics_of(r) == 1)]
    assert glance(partial_runs).headline.startswith("grid16-dospcot success, numerics 2 minus 1")
    assert glance(partial_runs).verdict == "non-inferior where measured; DoorKey not measured yet"
    # numerics 2 gaining 0.5 on every seed: outside the equivalence bound, yet non-inferior
    better = [r for r in runs if numerics_of(r) == 1]
    (tmp_path / "better").mkdir()
    better += [_run(tmp_path / "better", r.trial.config, r.trial.seed, 2, 1.0, 0.95) for r in list(better)]
    text = "\n".join(tables(better))
    assert text.count("**not met**") == 2 and glance(better).verdict == "numerics 2 non-inferior: adopt it"
    # a seed where numerics 2 loses every success: the lower end falls below -0.05
    runs = [r for r in runs if not (r.trial.seed == 1 and numerics_of(r) == 2)]
    (tmp_path / "lost").mkdir()
    runs.append(_run(tmp_path / "lost", "minigrid-doorkey-dospcot", 1, 2, 0.0, 0.95))
    assert glance(runs).verdict == "numerics 2 not shown non-inferior"


def test_doorkeys_numerics_1_arm_is_the_defaults_studys_version_1_sweep_read_for_doorkey_alone():
    """The preset alone under numerics 1 is one config whichever study names it: the numerics study
    reads DoorKey's from the defaults study's version-1 sweep, and none of that sweep's grid16 runs,
    whose seeds it has from the batched-seeds study."""
    study = STUDIES["numerics"]
    (reused,) = [s for s in study.sweeps if s.name == VERSION_SWEEPS[1].name]
    assert (reused.configs, reused.grid, reused.reads) == (
        VERSION_SWEEPS[1].configs,
        VERSION_SWEEPS[1].grid,
        ("minigrid-doorkey-dospcot",),
    )
    assert sweep_spec(reused, 20).trials(check_task=False) == sweep_spec(VERSION_SWEEPS[1], 20).trials(
        check_task=False
    )
    runs, _, _ = study_runs(study, Path(__file__).resolve().parents[2] / "runs" / "sweeps")
    from_defaults = [r for r in runs if "defaults" in r.trial.params]
    assert all(r.trial.config == "minigrid-doorkey-dospcot" for r in from_defaults)
    grid16_seeds = [r.trial.seed for r in runs if r.trial.config == "grid16-dospcot" and numerics_of(r) == 1]
    assert len(grid16_seeds) == len(set(grid16_seeds)) == 20


def test_the_numerics_3_study_pairs_numerics_3_with_numerics_1_and_2_by_the_adoption_rule(tmp_path):
    runs = []
    for preset in ("grid16-dospcot", "minigrid-doorkey-dospcot"):
        for seed in range(ADOPTION_SEEDS):
            runs.append(_run(tmp_path, preset, seed, 1, 0.5, 0.95))
            runs.append(_run(tmp_path, preset, seed, 2, 0.0, 0.95))
            runs.append(_run(tmp_path, preset, seed, 3, 0.5 + (0.1 if seed == 0 else 0.0), 0.95))
    text = "\n".join(tables_3(runs))
    assert "| `minigrid-doorkey-dospcot` | 3 | 0.505" in text and "| 300 CPU-s | 20 |" in text
    # the registered comparison, 3 minus 1, by the adoption rule alone (no equivalence bound), then
    # 3 minus 2 by the same rule (the amendment): numerics 3 gains 0.5 over numerics 2's 0.0 on every seed
    registered, amendment = text.split("Numerics 3 minus numerics 2")
    assert registered.count("**held**") == 4 and "+-0.1" not in text
    assert "success: 0.505 [0.500, 0.515] over 20 seeds" in amendment and amendment.count("**held**") == 4
    assert "| `grid16-dospcot` | 2 | 0.000" in text
    assert glance_3(runs).verdict == ADOPT_3
    assert glance_3(runs).headline == (
        f"minigrid-doorkey-dospcot success, numerics 3 minus 1, paired by seed: "
        f"{SeedSummary.of([0.1] + [0.0] * 19)}; minus 2: {SeedSummary.of([0.6] + [0.5] * 19)}"
    )
    assert glance_3([r for r in runs if numerics_of(r) != 3]).verdict == "not measured yet"
    assert "No preset holds a pair yet" in "\n".join(tables_3([r for r in runs if numerics_of(r) != 3]))
    # numerics 3 below numerics 2 on every seed, non-inferior to numerics 1: not adopted
    (tmp_path / "two").mkdir()
    worse_than_2 = [
        _run(tmp_path / "two", r.trial.config, r.trial.seed, 2, 1.0, 0.95) if numerics_of(r) == 2 else r
        for r in runs
    ]
    assert glance_3(worse_than_2).verdict == "numerics 3 not shown non-inferior"
    # numerics 2 missing on a preset: the move from numerics 2 waits for its pairs
    no_2 = [r for r in runs if not (numerics_of(r) == 2 and r.trial.config == "grid16-dospcot")]
    assert glance_3(no_2).verdict == "non-inferior where measured; a preset not measured yet"
    (tmp_path / "lost").mkdir()
    runs = [r for r in runs if not (r.trial.seed == 1 and numerics_of(r) == 3)]
    runs.append(_run(tmp_path / "lost", "grid16-dospcot", 1, 3, 0.0, 0.95))
    assert glance_3(runs).verdict == "numerics 3 not shown non-inferior"
    # its numerics-1 arm is the numerics study's, and its own sweep trains DoorKey's runs first
    sweeps = STUDIES["numerics-3"].sweeps
    assert sorted(s.name for s in sweeps[1:]) == sorted(s.name for s in STUDIES["numerics"].sweeps)
    assert all(s in STUDIES["numerics"].sweeps for s in sweeps[1:])
    assert sweep_spec(sweeps[0], 20).trials(check_task=False)[0].config == "minigrid-doorkey-dospcot"
