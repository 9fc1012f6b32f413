"""The sizing study (lab/studies/sizing.py) on hand-made runs: each patience is read off the capped
runs' curves at the round the library's rule stops them, and paired with the 5-round runs by seed."""

from pathlib import Path

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot.sweeps.sweep import Trial
from dospcot_lab.studies import STUDIES
from dospcot_lab.studies.sizing import (
    CAP,
    UNTUNED_FOLDER,
    UNTUNED_READ,
    UNTUNED_ROUNDS,
    UNTUNED_VERSION,
    glance,
    tables,
)

ORACLE = "minigrid-doorkey-oracle"


def _run(seed: int, success: list[float], capped: bool) -> TrialRun:
    """An oracle run of one agent whose greedy success per round is ``success``, its return the same
    and a random policy's 0.1 (so a round beats it from a success of 0.2 on)."""
    curves = [
        {"round": str(n), "success": str(s), "normalised_score": str(s - 0.1), "greedy_return": str(s)}
        for n, s in enumerate(success, 1)
    ]
    params = {"training.rounds": str(CAP)} if capped else {}
    summary = {"rounds": len(success), "mean": {"success": success[-1]}, "random_return": 0.1}
    return TrialRun(Trial(ORACLE, ORACLE, params, seed), summary, curves, Path())


def test_each_patience_is_read_where_the_rule_stops_the_capped_run():
    # Seed 0: a lucky 0.1, then nothing for two rounds (none beats a random policy's return, so they do
    # not count), a best of 0.6 in round 5, none in 6-7, 0.9 in round 8; seed 1 rises to 1.0 in round
    # 9, then holds it.
    early = [0.1, 0.0, 0.0, 0.2, 0.6, 0.5, 0.5, 0.9, 0.9, 0.9]
    late = [0.0, 0.3, 0.4, 0.5, 0.8, 0.85, 0.9, 0.95, 1.0, 1.0]
    runs = [
        _run(0, early + [1.0] * (CAP - 10), True),
        _run(1, late + [1.0] * (CAP - 10), True),
        _run(0, [0.0, 0.0, 0.1, 0.2, 0.2], False),
        _run(1, [0.0, 0.1, 0.2, 0.3, 0.4], False),
        _run(2, [0.0, 0.0, 0.0, 0.0, 0.5], False),  # no capped run: left out of the pairs
    ]
    lines = tables(runs)
    rows = {line.split(" | ")[1]: line for line in lines if line.startswith("| oracle |")}
    # Patience 2 stops seed 0 after round 7 (0.5) and seed 1 after round 11 (two ties of its best).
    assert rows["cap 20, patience 2"].startswith(
        f"| oracle | cap 20, patience 2 | {SeedSummary.of([0.5, 1.0])} | 9.0 |"
    )
    # Patience 3 carries seed 0 past round 8 to 1.0 in round 11 and stops it after round 14; seed 1
    # after round 12.
    assert f"| {SeedSummary.of([1.0, 1.0])} | 13.0 |" in rows["cap 20, patience 3"]
    assert rows["5 rounds (the preset)"].endswith("| 5.0 | every reward | 2 |")
    assert rows["20 rounds"].startswith(f"| oracle | 20 rounds | {SeedSummary.of([1.0, 1.0])} | 20.0 |")
    diff = SeedSummary.of([1.0 - 0.2, 1.0 - 0.4])
    assert f"- oracle, cap 20, patience 3 minus 5 rounds, success paired by seed: {diff}" in lines
    assert glance(runs).headline.endswith(f"paired: {diff}")


def test_the_capped_sweeps_are_the_budget_studys_unlock_arms_with_more_rounds():
    sweeps = {sweep.name: sweep for sweep in STUDIES["sizing"].sweeps}
    for arm in ("oracle", "dospcot"):
        five, capped = sweeps[f"budget-confirm-unlock-{arm}"], sweeps[f"sizing-unlock-{arm}-{CAP}"]
        assert capped.grid == {**five.grid, "training.rounds": (str(CAP),)}
        assert (capped.configs, capped.numerics) == (five.configs, five.numerics)


def test_each_variant_is_the_preset_oracle_with_one_setting_as_a_bare_config_has_it_paired_by_seed():
    sweeps = {sweep.name: sweep for sweep in STUDIES["sizing"].sweeps}
    five = sweeps["budget-confirm-unlock-oracle"]
    assert sweeps["sizing-unlock-oracle-actions"].grid == {**five.grid, "gym.wrappers": ("[]",)}
    assert sweeps["sizing-unlock-oracle-esarsa"].grid == {**five.grid, "agent": ("esarsa_dqn",)}
    preset = [_run(seed, [0.0] * 4 + [s], False) for seed, s in enumerate([0.2, 0.7, 0.0])]
    actions = [
        TrialRun(Trial(ORACLE, ORACLE, {"gym.wrappers": "[]"}, seed), {"mean": {"success": s}}, [], Path())
        for seed, s in ((0, 0.0), (1, 0.1))
    ]
    lines = tables([*preset, *actions])
    diff = SeedSummary.of([0.0 - 0.2, 0.1 - 0.7])
    mine, theirs = SeedSummary.of([0.0, 0.1]), SeedSummary.of([0.2, 0.7])
    assert f"| oracle, seven actions | {mine} | {theirs} | {diff} | 2 |" in lines
    assert not any(line.startswith("| oracle, esarsa_dqn |") for line in lines)  # not run: no row
    # A variant run is no 5-round run of the preset's oracle.
    assert next(line for line in lines if "| 5 rounds (the preset) |" in line).endswith("| 3 |")


def test_the_untuned_oracle_under_the_adopted_defaults_is_read_at_its_rounds_per_agent():
    sweep = next(
        s for s in STUDIES["sizing"].sweeps if s.name == f"sizing-unlock-untuned-oracle-{UNTUNED_ROUNDS}"
    )
    assert sweep.configs == (f"{UNTUNED_FOLDER}/unlock-oracle.toml",)
    assert (sweep.defaults, sweep.numerics) == (UNTUNED_VERSION, None)
    config = f"{UNTUNED_FOLDER}/unlock-oracle.toml"

    def run(seed: int, agent: str, success: list[float]) -> TrialRun:
        curves = [{"round": str(n), "success": str(s)} for n, s in enumerate(success, 1)]
        params = {"training.rounds": str(UNTUNED_ROUNDS), "agent": agent}
        return TrialRun(Trial(config, "untuned-unlock-oracle", params, seed), {}, curves, Path())

    rising = [n / UNTUNED_ROUNDS for n in range(1, UNTUNED_ROUNDS + 1)]  # 1.0 at its last round
    runs = [
        run(100, "dqn", rising),
        run(101, "dqn", [0.0] * 9 + [0.9] + [0.5] * (UNTUNED_ROUNDS - 10)),
        run(102, "dqn", [0.0] * 12),  # not finished: left out
        _run(100, [0.0] * 5, False),  # the preset's oracle: its own rows, untouched
    ]
    lines = tables(runs)
    row = next(line for line in lines if line.startswith("| dqn |"))
    read = [
        SeedSummary.of([n / UNTUNED_ROUNDS, 0.0 if n < 10 else (0.9 if n == 10 else 0.5)])
        for n in UNTUNED_READ
    ]
    best = SeedSummary.of([1.0, 0.9])
    assert row == f"| dqn | {' | '.join(map(str, read))} | {best} | 1 of 2 |"
    assert not any(line.startswith("| esarsa_dqn |") for line in lines)  # not run: no row
    assert next(line for line in lines if "| 5 rounds (the preset) |" in line).endswith("| 1 |")
