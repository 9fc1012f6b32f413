"""The true-rewards study (lab/studies/true_rewards.py) on hand-made runs: the gap from DOSPCoT to the
oracle splits, paired by seed, into the path's loss and the pseudo-rewards' loss, and the control
matches the oracle only where its interval holds 0 above the margin."""

import json
from pathlib import Path

import pytest

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import STUDIES
from dospcot_lab.studies.true_rewards import (
    ADOPTED_PATH,
    ADOPTED_VERSION,
    EARLY_LABELS,
    EARLY_PATH,
    EARLY_VERSION,
    MARGIN,
    PRESET,
    PSEUDO_REWARDS,
    WAIT,
    glance,
    matches,
    tables,
)


def _run(
    config: str, seed: int, success: float, params: dict[str, str] | None = None, defaults: int = 1
) -> TrialRun:
    """A run under version ``defaults`` of the defaults whose image agent succeeds in ``success`` of its
    episodes; a co-trained run's ego agent never does (the oracle trains the image agent alone, so the
    ego agent enters no difference)."""
    views = ["image"] if config.endswith("-oracle") else ["image", "ego"]
    per_view = {
        view: {
            "success": success if view == "image" else 0.0,
            "agreement": 0.5,
            "pseudo_accuracy": 1.0,
            "coverage": 0.5,
        }
        for view in views
    }
    summary = {"views": views, "per_view": per_view, "mean": {}}
    return TrialRun(Trial(config, config, params or {}, seed, defaults=defaults), summary, [], Path())


def _lavagap(control: list[float], oracle: list[float], dospcot: list[float]) -> list[TrialRun]:
    hidden = {PSEUDO_REWARDS: "hidden", "training.label_fraction": "0.1"}
    uniform = {"training.label_strategy": "uniform", "training.label_fraction": "0.1"}
    other = {"training.label_strategy": "random", "training.label_fraction": "0.1"}
    return [
        *(_run("minigrid-lavagap-dospcot", s, v, hidden) for s, v in enumerate(control)),
        *(_run("minigrid-lavagap-oracle", s, v) for s, v in enumerate(oracle)),
        *(_run("minigrid-lavagap-dospcot", s, v, uniform) for s, v in enumerate(dospcot)),
        # Another strategy of the active-queries sweep read here: no arm of this study.
        *(_run("minigrid-lavagap-dospcot", s, 0.0, other) for s in range(len(dospcot))),
    ]


def test_the_gap_splits_into_the_path_and_the_pseudo_rewards_paired_by_seed():
    control, oracle, dospcot = [1.0, 0.5, 1.0, 1.0], [1.0, 1.0, 1.0, 0.5], [0.5, 0.5, 1.0, 0.0]
    lines = tables(_lavagap(control, oracle, dospcot))
    path = SeedSummary.of([c - o for c, o in zip(control, oracle, strict=True)])
    pseudo = SeedSummary.of([d - c for d, c in zip(dospcot, control, strict=True)])
    whole = SeedSummary.of([d - o for d, o in zip(dospcot, oracle, strict=True)])
    assert f"- LavaGapS7 (image), path: control minus oracle: {path} over 4 seeds; " in "\n".join(lines)
    assert f"- LavaGapS7 (image), pseudo-rewards: DOSPCoT minus control: {pseudo} over 4 seeds." in lines
    assert f"- LavaGapS7 (image), whole gap: DOSPCoT minus oracle: {whole} over 4 seeds." in lines
    rows = {" | ".join(line.split(" | ")[:2]): line for line in lines if line.startswith("| ")}
    assert rows["| DOSPCoT | image"].startswith(f"| DOSPCoT | image | {SeedSummary.of(dospcot)} |")
    assert rows["| DOSPCoT | ego"].startswith(f"| DOSPCoT | ego | {SeedSummary.of([0.0] * 4)} |")
    assert rows["| DOSPCoT | image"].endswith("| 4 |")  # the other strategy's runs are no arm of it
    assert "| oracle | ego" not in rows


@pytest.mark.parametrize(
    ("control", "matched"),
    [
        ([1.0] * 10, True),  # equal on every seed: an interval of width 0 at 0
        ([1.0] * 8 + [0.0] * 2, False),  # lower end well below -0.1
        ([1.0, 0.0] * 5, False),
    ],
)
def test_the_control_matches_only_within_the_margin(control, matched):
    runs = _lavagap(control, [1.0] * 10, [0.0] * 10)
    diff = SeedSummary.of([c - 1.0 for c in control])
    assert matches(diff) is matched
    verdict = "**matches the oracle**" if matched else "**does not match the oracle**"
    assert f"- LavaGapS7 (image), path: control minus oracle: {diff} over 10 seeds; {verdict}." in tables(
        runs
    )
    assert glance(runs).headline.endswith(f"(matches on {int(matched)} of 1 tasks judged, of 4)")


def test_the_adopted_versions_control_pairs_with_its_own_oracle_and_round_1s_wait_splits_its_loss():
    v = ADOPTED_VERSION
    oracle, waiting, control = [1.0, 1.0, 0.5, 1.0], [1.0, 0.5, 0.5, 1.0], [0.5, 0.5, 0.5, 1.0]
    runs = [
        *_lavagap([0.0] * 4, [0.0] * 4, [0.0] * 4),  # version 1's arms, all at 0: no part of these pairs
        *(_run("minigrid-lavagap-oracle", s, x, defaults=v) for s, x in enumerate(oracle)),
        *(_run("minigrid-lavagap-oracle", s, x, WAIT, defaults=v) for s, x in enumerate(waiting)),
        *(
            _run("minigrid-lavagap-dospcot", s, x, {PSEUDO_REWARDS: "hidden"}, v)
            for s, x in enumerate(control)
        ),
    ]
    lines = tables(runs)
    path = SeedSummary.of([c - o for c, o in zip(control, oracle, strict=True)])
    wait = SeedSummary.of([w - o for w, o in zip(waiting, oracle, strict=True)])
    beyond = SeedSummary.of([c - w for c, w in zip(control, waiting, strict=True)])
    assert (
        f"- LavaGapS7 (image), {ADOPTED_PATH}: {path} over 4 seeds; **does not match the oracle**." in lines
    )
    named = "oracle, round 1 at random"
    assert (
        f"- LavaGapS7 (image), round 1's wait alone: {named} minus oracle, version {v}: {wait} over 4 seeds."
        in lines
    )
    assert (
        f"- LavaGapS7 (image), beyond round 1's wait, version {v}: its control minus {named}: {beyond} "
        "over 4 seeds." in lines
    )
    rows = {" | ".join(line.split(" | ")[:2]): line for line in lines if line.startswith("| ")}
    assert rows[f"| {named} | image"].startswith(f"| {named} | image | {SeedSummary.of(waiting)} |")
    # The headline reads the adopted version once its control has run.
    assert glance(runs).headline.startswith(
        f"success of the oracle's agents under version {v} of the defaults"
    )
    assert f"LavaGapS7 {path}" in glance(runs).headline


def test_early_labels_pair_with_the_adopted_oracle_and_control_and_train_the_adopted_presets():
    v = ADOPTED_VERSION
    oracle, control, early = [1.0, 1.0, 0.5, 1.0], [0.5, 0.5, 0.5, 1.0], [1.0, 0.5, 0.5, 1.0]
    runs = [
        *(_run("minigrid-doorkey-oracle", s, x, defaults=v) for s, x in enumerate(oracle)),
        *(
            _run("minigrid-doorkey-dospcot", s, x, {PSEUDO_REWARDS: "hidden"}, v)
            for s, x in enumerate(control)
        ),
        *(_run("minigrid-doorkey-dospcot", s, x, EARLY_LABELS, v) for s, x in enumerate(early)),
    ]
    lines = tables(runs)
    path = SeedSummary.of([e - o for e, o in zip(early, oracle, strict=True)])
    alone = SeedSummary.of([e - c for e, c in zip(early, control, strict=True)])
    named = f"control v{v}, early labels"
    assert (
        f"- DoorKey-5x5 (image), path under early labels, version {v}: {named} minus oracle, version {v}: "
        f"{path} over 4 seeds; the rule is read once all 10 pairs have run." in lines
    )
    alone_line = f"- DoorKey-5x5 (image), early labels alone: {named} minus control, version {v}: {alone}"
    assert f"{alone_line} over 4 seeds." in lines
    sweeps = {sweep.name: sweep for sweep in STUDIES["true-rewards"].sweeps}
    for task in ("doorkey", "lavagap", "fasthighway", "grid16"):
        sweep = sweeps[f"true-rewards-{task}-early-labels-v{v}"]
        assert sweep.defaults == v and sweep.grid == {k: (x,) for k, x in EARLY_LABELS.items()}
        assert sweep.configs == sweeps[f"true-rewards-{task}-v{v}"].configs


def test_the_extended_tasks_pair_early_labels_with_the_oracle_over_their_seeds_and_the_rest_over_ten():
    v = ADOPTED_VERSION
    hidden = {PSEUDO_REWARDS: "hidden"}
    oracle, early = [1.0] * 20, [1.0] * 19 + [0.5]
    runs = [
        *(_run("minigrid-lavagap-oracle", s, x, defaults=v) for s, x in enumerate(oracle)),
        *(_run("minigrid-lavagap-dospcot", s, x, EARLY_LABELS, v) for s, x in enumerate(early)),
        # The version's control trains ten seeds: a run past them is not read.
        *(_run("minigrid-lavagap-dospcot", s, 1.0, hidden, v) for s in range(11)),
    ]
    lines = tables(runs)
    path = SeedSummary.of([e - o for e, o in zip(early, oracle, strict=True)])
    named = f"control v{v}, early labels"
    assert any(f"{named} minus oracle, version {v}: {path} over 20 seeds" in line for line in lines)
    assert any(f"{ADOPTED_PATH}: 0.000" in line and "over 10 seeds" in line for line in lines)
    # 19 differences of 0 and one of -0.5: sd 0.1118, (2.8016 * 0.1118 / 0.1) ** 2 = 9.81, so 10 pairs.
    assert any("seeds the rule needs" in line and ", 10 pairs give" in line for line in lines)
    sweeps = {sweep.name: sweep for sweep in STUDIES["true-rewards"].sweeps}
    for task, seeds in (("lavagap", 40), ("grid16", 40), ("doorkey", 10), ("fasthighway", 100)):
        for arm in ("early-labels", "oracle"):
            assert sweeps[f"true-rewards-{task}-{arm}-v{v}"].seeds == seeds
        assert sweeps[f"true-rewards-{task}-v{v}"].seeds == 10


def test_the_glance_reads_version_14s_control_once_the_early_labels_arm_has_run_on_every_task():
    v = ADOPTED_VERSION
    configs = PRESET
    runs = [_run(f"{c}-oracle", s, 1.0, defaults=v) for c in configs.values() for s in range(3)]
    runs += [
        _run(f"{c}-dospcot", s, 1.0, {PSEUDO_REWARDS: "hidden"}, v)
        for c in configs.values()
        for s in range(3)
    ]
    early = [_run(f"{c}-dospcot", s, 0.5, EARLY_LABELS, v) for c in configs.values() for s in range(3)]
    # On three tasks of four the glance still reads the adopted version's control.
    assert glance(runs + early[:9]).headline.startswith(f"success of the oracle's agents under version {v} ")
    found = glance(runs + early)
    assert found.headline.startswith(f"success of the oracle's agents under version {EARLY_VERSION} ")
    assert f"DoorKey-5x5 {SeedSummary.of([-0.5] * 3)}" in found.headline
    assert found.seeds == (0, 1, 2)


def test_matches_needs_zero_inside_and_the_lower_end_above_the_margin():
    assert not matches(SeedSummary(0.2, 0.1, 0.3, 0.2, 10))  # above the oracle: not "within noise"
    assert not matches(SeedSummary(-0.05, -MARGIN, 0.0, -0.05, 10))  # the lower end at the margin
    assert matches(SeedSummary(-0.02, -0.09, 0.04, -0.02, 10))


def test_the_controls_are_the_compared_dospcot_runs_with_the_true_rewards():
    sweeps = {sweep.name: sweep for sweep in STUDIES["true-rewards"].sweeps}
    for task in ("lavagap", "doorkey", "fasthighway"):
        control, dospcot = sweeps[f"true-rewards-{task}"], sweeps[f"queries-{task}-dospcot"]
        assert control.configs == dospcot.configs
        assert control.grid["training.label_fraction"] == dospcot.grid["training.label_fraction"]
        assert control.grid[PSEUDO_REWARDS] == ("hidden",)
        assert control.numerics == dospcot.numerics == 1
    assert sweeps["true-rewards-grid16"].configs == ("grid16-dospcot",)


def test_exploration_by_rounds_is_a_second_control_compared_with_the_control_and_the_oracle():
    rounds = {PSEUDO_REWARDS: "hidden", "training.label_fraction": "0.1", "training.exploration": "rounds"}
    runs = _lavagap([0.0, 0.5, 0.5], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    runs += [_run("minigrid-lavagap-dospcot", s, 1.0, rounds) for s in range(2)]
    lines = tables(runs)
    gain = SeedSummary.of([1.0 - 0.0, 1.0 - 0.5])
    assert (
        f"- LavaGapS7 (image), exploration by rounds: its control minus the control: {gain} over 2 seeds."
        in lines
    )
    path = SeedSummary.of([0.0, 0.0])
    assert (
        f"- LavaGapS7 (image), path under exploration by rounds: its control minus oracle: {path} over 2 "
        "seeds; **matches the oracle**."
    ) in lines
    assert glance(runs).headline.endswith("(matches on 0 of 1 tasks judged, of 4)")  # the control's alone
    sweeps = {sweep.name: sweep for sweep in STUDIES["true-rewards"].sweeps}
    by_rounds = sweeps["true-rewards-lavagap-rounds"]
    assert by_rounds.grid == {**sweeps["true-rewards-lavagap"].grid, "training.exploration": ("rounds",)}


def test_shorter_rounds_are_a_diagnosis_of_their_own_told_apart_from_exploration_by_rounds_alone():
    hidden = {PSEUDO_REWARDS: "hidden", "training.label_fraction": "0.1", "training.exploration": "rounds"}
    short = {
        **hidden,
        "training.exploration": "rounds",
        "training.rounds": "20",
        "training.steps_per_round": "2500",
    }
    runs = _lavagap([0.5, 0.5], [1.0, 1.0], [0.0, 0.0])
    runs += [_run("minigrid-lavagap-dospcot", s, 1.0, short) for s in range(2)]
    runs += [_run("minigrid-lavagap-dospcot", s, 0.5, hidden) for s in range(2)]
    lines = tables(runs)
    what = "exploration by rounds and 20 rounds of 2,500 steps"
    zero, half = SeedSummary.of([0.0, 0.0]), SeedSummary.of([0.5, 0.5])
    assert f"- LavaGapS7 (image), {what}: its control minus the control: {half} over 2 seeds." in lines
    assert (
        f"- LavaGapS7 (image), exploration by rounds: its control minus the control: {zero} over 2 seeds."
        in lines
    )
    # A hidden-rewards run with settings no diagnosis names belongs to no arm.
    odd = {**hidden, "training.rounds": "7"}
    assert tables([*runs, _run("minigrid-lavagap-dospcot", 0, 0.0, odd)]) == lines
    sweeps = {sweep.name: sweep for sweep in STUDIES["true-rewards"].sweeps}
    for task in ("doorkey", "lavagap"):
        grid = sweeps[f"true-rewards-{task}-short-rounds"].grid
        assert grid["training.rounds"] == ("20",) and grid["training.steps_per_round"] == ("2500",)


@pytest.mark.parametrize(
    ("added", "alone", "arm", "suffix"),
    [
        (
            {"training.cotrain_passes": "4"},
            "4 co-training passes a round",
            "control, 4 passes a round",
            "passes",
        ),
        (
            {"training.cotrain_passes": "10", "training.pass_kind": "score"},
            "10 score passes a round",
            "control, 10 score passes",
            "score-passes",
        ),
    ],
)
def test_passes_inside_the_rounds_are_compared_with_exploration_by_rounds_alone(added, alone, arm, suffix):
    """The passes diagnoses (co-training passes, score passes) differ from exploration by rounds in
    their passes alone, so besides the control and the oracle each is paired with that diagnosis,
    seed by seed."""
    rounds = {PSEUDO_REWARDS: "hidden", "training.label_fraction": "0.1", "training.exploration": "rounds"}
    runs = _lavagap([0.0, 0.0], [1.0, 1.0], [0.0, 0.0])
    runs += [_run("minigrid-lavagap-dospcot", s, v, rounds) for s, v in enumerate([0.5, 0.0])]
    runs += [_run("minigrid-lavagap-dospcot", s, 1.0, {**rounds, **added}) for s in range(2)]
    lines = tables(runs)
    assert (
        f"- LavaGapS7 (image), {alone} alone: {arm} minus control, exploration by rounds: "
        f"{SeedSummary.of([0.5, 1.0])} over 2 seeds." in lines
    )
    assert any(line.startswith(f"| {arm} | image | 1.000") for line in lines)
    sweeps = {sweep.name: sweep for sweep in STUDIES["true-rewards"].sweeps}
    for task in ("doorkey", "lavagap"):
        sweep = sweeps[f"true-rewards-{task}-{suffix}"]
        grid = {key: (value,) for key, value in added.items()}
        assert sweep.grid == {**sweeps[f"true-rewards-{task}-rounds"].grid, **grid}
        assert sweep.seeds == 10


def test_pairs_with_the_oracle_trained_on_two_cpu_models_are_counted_per_arm(tmp_path):
    """Two CPU models round differently: a control paired with an oracle run from another model says so."""
    runs = _lavagap([1.0, 1.0], [1.0, 1.0], [1.0, 1.0])
    for i, run in enumerate(runs):
        run_dir = tmp_path / str(i)
        run_dir.mkdir()
        intel = run.trial.params.get(PSEUDO_REWARDS) == "hidden" and run.trial.seed == 0
        cpu = ("Xeon" if intel else "EPYC") + ", torch kernels AVX512"
        (run_dir / "run_info.json").write_text(json.dumps({"cpu": cpu}))
        runs[i] = TrialRun(run.trial, run.summary, [], run_dir)
    assert tables(runs)[-1].startswith(
        "Pairs with the oracle trained on two CPU models (`run_info.json`'s `cpu`): control: 1 of 2; "
        "DOSPCoT: 0 of 2."
    )
    # runs that recorded no CPU (a folder without run_info.json) add no line
    assert not tables(_lavagap([1.0], [1.0], [1.0]))[-1].startswith("Pairs with the oracle")


def _with_rounds(run: TrialRun, successes: list[float], steps: int) -> TrialRun:
    """``run`` whose agents on each view succeeded in ``successes[i]`` of the episodes after round i + 1
    of ``steps`` env steps (the ego agent, as in :func:`_run`, never)."""
    rows = [
        {"round": float(i + 1), "view": view, "env_steps": float(steps * (i + 1)), "success": value}
        for i, success in enumerate(successes)
        for view, value in (("image", success), ("ego", 0.0))
        if view in run.summary["views"]
    ]
    return TrialRun(run.trial, run.summary, rows, run.run_dir)


def test_success_by_steps_reads_each_arm_at_the_oracles_round_ends_on_its_views():
    hidden = {PSEUDO_REWARDS: "hidden", "training.label_fraction": "0.1"}
    short = {
        **hidden,
        "training.exploration": "rounds",
        "training.rounds": "20",
        "training.steps_per_round": "2500",
    }
    runs = [
        _with_rounds(_run("minigrid-lavagap-oracle", 0, 1.0), [0.5, 1.0], 10_000),
        _with_rounds(_run("minigrid-lavagap-oracle", 1, 1.0), [0.0, 1.0], 10_000),
        _with_rounds(_run("minigrid-lavagap-dospcot", 0, 0.5, hidden), [0.0, 0.5], 10_000),
        _with_rounds(_run("minigrid-lavagap-dospcot", 1, 0.5, hidden), [0.0, 0.5], 10_000),
        # rounds of a quarter of the oracle's: read at its 4th and 8th round, where the oracle's end
        _with_rounds(
            _run("minigrid-lavagap-dospcot", 0, 1.0, short), [0, 0.1, 0.2, 0.3, 0, 0, 0, 0.9], 2_500
        ),
    ]
    lines = tables(runs)
    assert "| arm | 10,000 steps | 20,000 steps | seeds |" in lines
    assert "| oracle | 0.25 | 1.00 | 2 |" in lines  # (0.5 + 0) / 2, (1 + 1) / 2
    assert "| control | 0.00 | 0.50 | 2 |" in lines  # the ego agent is not on the oracle's view
    assert "| control, 20 short rounds | 0.30 | 0.90 | 1 |" in lines


def test_the_early_labels_path_is_judged_only_once_every_declared_pair_has_run():
    v = ADOPTED_VERSION
    hidden = {PSEUDO_REWARDS: "hidden"}
    runs = [_run("minigrid-doorkey-dospcot", s, 1.0, hidden, v) for s in range(10)]
    runs += [_run("minigrid-doorkey-oracle", s, 1.0, defaults=v) for s in range(10)]
    early = [_run("minigrid-doorkey-dospcot", s, 1.0, EARLY_LABELS, v) for s in range(10)]
    for task, preset in PRESET.items():  # the glance reads the early-labels path once it ran on every task
        if task != "doorkey":
            runs += [
                _run(f"{preset}-oracle", 0, 1.0, defaults=v),
                _run(f"{preset}-dospcot", 0, 1.0, EARLY_LABELS, v),
            ]
    line = f"- DoorKey-5x5 (image), {EARLY_PATH}: {SeedSummary.of([0.0] * 9)} over 9 seeds"
    assert f"{line}; the rule is read once all 10 pairs have run." in tables(runs + early[:9])
    # Nine of ten pairs equal: an interval of 0 that would match, not yet judged, nor counted as held.
    assert glance(runs + early[:9]).headline.endswith("(matches on 0 of 0 tasks judged, of 4)")
    line = f"- DoorKey-5x5 (image), {EARLY_PATH}: {SeedSummary.of([0.0] * 10)} over 10 seeds"
    assert f"{line}; **matches the oracle**." in tables(runs + early)
    assert glance(runs + early).headline.endswith("(matches on 1 of 1 tasks judged, of 4)")
