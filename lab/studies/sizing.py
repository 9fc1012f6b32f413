"""The sizing study (exploratory): how long to train on a task no preset was sized for.

MiniGrid-Unlock-v0 under the DoorKey presets' settings, as the budget study's B4 arms ran it (5
rounds of 10,000 steps, its oracle at 0.240), against the same runs capped at :data:`CAP` rounds. A
stop by the greedy evaluation's patience (``training.stop_patience``) leaves the rounds before it as
the capped run trained them, so each patience's outcome is read off the capped runs' curves with the
library's own rule (:class:`~dospcot.core.stopping.GreedyPatience`), with no run of its own. A last arm
trains the untuned study's Unlock oracle itself under the adopted defaults for :data:`UNTUNED_ROUNDS`
rounds, under two agents."""

from __future__ import annotations

import dataclasses
import math

from dospcot.core.stopping import GreedyPatience
from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.budget_confirm import SWEEPS as BUDGET_SWEEPS
from dospcot_lab.studies.declaration import EXPLORATORY, Glance, Study, Sweep
from dospcot_lab.studies.untuned import FOLDER as UNTUNED_FOLDER
from dospcot_lab.studies.untuned import ORACLE_FLOOR

CAP = 20
"""The capped arms' rounds."""
PATIENCES = (2, 3, 4)
"""The patiences read off the capped curves."""
ARMS = ("oracle", "dospcot")
PRESET_LENGTH = "5 rounds (the preset)"
"""The budget study's runs, read on the seeds the capped arm has run (all ten before it has any)."""
FIRST_SEED, SEEDS = 100, 5
"""The budget study's Unlock seeds (its arms ran 100-109); the capped arms run the first five."""


UNTUNED_VERSION = 14
"""The version of the defaults the untuned study's Unlock oracle trains under here: the adopted one when
its sweep was declared (pinned, so the sweep keeps it when the default moves)."""
UNTUNED_ROUNDS = 30
"""The rounds of that oracle's runs: six times the version's 5."""
UNTUNED_AGENTS = ("esarsa_dqn", "dqn")
"""Its agents: the version's, and the DoorKey presets' (the max target with windows cut at exploratory
actions)."""
UNTUNED_READ = (5, 10, 20, 30)
"""The rounds its table reads."""


def _untuned() -> Sweep:
    """The untuned study's Unlock oracle (a config naming only the env id and its view) under
    :data:`UNTUNED_VERSION`, for :data:`UNTUNED_ROUNDS` rounds, under each of :data:`UNTUNED_AGENTS`."""
    grid = {"training.rounds": (str(UNTUNED_ROUNDS),), "agent": UNTUNED_AGENTS}
    return Sweep(
        f"sizing-unlock-untuned-oracle-{UNTUNED_ROUNDS}",
        (f"{UNTUNED_FOLDER}/unlock-oracle.toml",),
        grid,
        numerics=None,
        defaults=UNTUNED_VERSION,
    )


def _five_rounds(arm: str) -> Sweep:
    """The budget study's Unlock sweep of ``arm`` (5 rounds), read here with its own ten seeds."""
    sweep = next(s for s in BUDGET_SWEEPS if s.name == f"budget-confirm-unlock-{arm}")
    return dataclasses.replace(sweep, seeds=10)


def _capped(arm: str) -> Sweep:
    sweep = _five_rounds(arm)
    grid = {**sweep.grid, "training.rounds": (str(CAP),)}
    return dataclasses.replace(sweep, name=f"sizing-unlock-{arm}-{CAP}", grid=grid, seeds=None)


VARIANTS = {
    "oracle, seven actions": ("actions", {"gym.wrappers": "[]"}),
    "oracle, esarsa_dqn": ("esarsa", {"agent": "esarsa_dqn"}),
}
"""Per arm, its sweep's suffix and the setting it changes: the oracle at the preset's length with one
of the preset's settings set back to what a config that names only the env id gets: MiniGrid's whole
action set (the preset's ``DoorActions`` leaves out drop and done), and the adopted defaults' agent
(the preset's is ``dqn``). Added after runs outside the record (seeds 0-5, trained as batches) had read
almost no success under either, where the preset's oracle had opened the door on most of them: the
untuned study's Unlock oracle differs from the preset in both."""


def _variant(name: str) -> Sweep:
    sweep = _five_rounds("oracle")
    suffix, params = VARIANTS[name]
    grid = {**sweep.grid, **{k: (v,) for k, v in params.items()}}
    return dataclasses.replace(sweep, name=f"sizing-unlock-oracle-{suffix}", grid=grid, seeds=None)


def _arm(run: TrialRun) -> str:
    if run.trial.config.startswith(UNTUNED_FOLDER):
        return f"untuned, {run.trial.params['agent']}"
    variant = next(
        (name for name, (_, params) in VARIANTS.items() if params.items() <= run.trial.params.items()), None
    )
    return variant or ("oracle" if run.trial.config.endswith("-oracle") else "dospcot")


def _per_round(run: TrialRun) -> list[list[dict]]:
    """A run's ``metrics.csv`` rows, one list per round (one row per agent)."""
    rounds: dict[int, list[dict]] = {}
    for row in run.curves:
        rounds.setdefault(int(row["round"]), []).append(row)
    return [rounds[r] for r in sorted(rounds)]


def _stop(rounds: list[list[dict]], random_return: float, patience: int) -> int:
    """The round (1-based) after which ``patience`` would have stopped a capped run of these
    :func:`_per_round` rows, else its last."""
    rule = GreedyPatience(patience, random_return)
    for number, rows in enumerate(rounds, 1):
        if rule.update(
            [{k: float(r[k]) for k in ("success", "normalised_score", "greedy_return")} for r in rows]
        ):
            return number
    return len(rounds)


def _mean(rows: list[dict], key: str) -> float:
    """One round's ``key``, mean over the run's agents (NaN where the runs did not record it)."""
    values = [float(row.get(key, math.nan)) for row in rows]
    return sum(values) / len(values)


def _end(rounds: list[list[dict]], number: int) -> tuple[float, int, float]:
    """(success, rounds trained, labels held) of a run stopped after round ``number``."""
    rows = rounds[number - 1]
    return _mean(rows, "success"), number, _mean(rows, "labelled_steps")


def _rules(runs: list[TrialRun], arm: str) -> dict[str, dict[int, tuple[float, int, float]]]:
    """Per length rule, per seed: (success, rounds trained, labels held) at the end it gives."""
    capped = {r.trial.seed: r for r in runs if _arm(r) == arm and "training.rounds" in r.trial.params}
    five = {
        r.trial.seed: r
        for r in runs
        if _arm(r) == arm and "training.rounds" not in r.trial.params
        if not capped or r.trial.seed in capped
    }
    preset = {seed: _per_round(r) for seed, r in five.items()}
    rounds = {seed: _per_round(r) for seed, r in capped.items()}
    rules = {PRESET_LENGTH: {seed: _end(rows, len(rows)) for seed, rows in preset.items()}}
    for patience in PATIENCES:
        rules[f"cap {CAP}, patience {patience}"] = {
            seed: _end(rounds[seed], _stop(rounds[seed], r.summary["random_return"], patience))
            for seed, r in capped.items()
        }
    rules[f"{CAP} rounds"] = {seed: _end(rows, len(rows)) for seed, rows in rounds.items()}
    return rules


def tables(runs: list[TrialRun]) -> list[str]:
    """Per arm and length rule: success, rounds trained and labels held over seeds; then each rule's
    success minus the preset's 5 rounds, paired by seed."""
    lines = [
        f"Each capped run trains {CAP} rounds; a patience's row is each capped run read at the round its "
        "rule would have stopped it (rounds in a row with no new best greedy evaluation, counted once a "
        "round's greedy return beat a random policy's). The 5-round rows are the budget study's own "
        "runs, whose exploration falls over 5 rounds rather than 20.",
        "",
        "| arm | length | success | rounds trained | labels held | seeds |",
        "|---|---|---|---|---|---|",
    ]
    differences, bases = [], {}
    for arm in ARMS:
        rules = _rules(runs, arm)
        base = bases[arm] = rules[PRESET_LENGTH]
        for rule, by_seed in rules.items():
            if not by_seed:
                continue
            success, rounds, labels = (SeedSummary.of([v[i] for v in by_seed.values()]) for i in range(3))
            labelled = "every reward" if arm == "oracle" else f"{labels.mean:.0f}"
            lines.append(f"| {arm} | {rule} | {success} | {rounds.mean:.1f} | {labelled} | {len(by_seed)} |")
            seeds = sorted(set(base) & set(by_seed))
            if rule != PRESET_LENGTH and seeds:
                diff = SeedSummary.of([by_seed[s][0] - base[s][0] for s in seeds])
                differences.append(f"- {arm}, {rule} minus 5 rounds, success paired by seed: {diff}")
    return [*lines, "", *differences, *_variants(runs, bases["oracle"]), *_untuned_lines(runs)]


def _variants(runs: list[TrialRun], oracle: dict[int, tuple[float, int, float]]) -> list[str]:
    """Each :data:`VARIANTS` arm's success at the preset's length beside the oracle's there (``oracle``,
    its 5-round rule by seed), paired by seed."""
    base = {seed: v[0] for seed, v in oracle.items()}
    lines = []
    for name in VARIANTS:
        mine = {r.trial.seed: r.summary["mean"]["success"] for r in runs if _arm(r) == name}
        seeds = sorted(set(base) & set(mine))
        if seeds:
            diff = SeedSummary.of([mine[s] - base[s] for s in seeds])
            ours, theirs = SeedSummary.of([mine[s] for s in seeds]), SeedSummary.of([base[s] for s in seeds])
            lines.append(f"| {name} | {ours} | {theirs} | {diff} | {len(seeds)} |")
    header = [
        "",
        "The oracle at the preset's 5 rounds with one of its settings as a config naming only the env id "
        "would have it, against the preset's oracle on the same seeds (success, last round; the difference "
        "paired by seed):",
        "",
        "| arm | success | the preset's oracle | difference | seeds |",
        "|---|---|---|---|---|",
    ]
    return [*header, *lines] if lines else []


def _untuned_lines(runs: list[TrialRun]) -> list[str]:
    """Per agent of the :func:`_untuned` sweep, over its finished runs: the success at each of
    :data:`UNTUNED_READ`'s rounds and at each run's best round, and the runs whose last round reached the
    untuned study's floor for the oracle."""
    lines = []
    for agent in UNTUNED_AGENTS:
        mine = [_per_round(r) for r in runs if _arm(r) == f"untuned, {agent}"]
        done = [rounds for rounds in mine if len(rounds) >= UNTUNED_ROUNDS]
        if not done:
            continue
        read = [SeedSummary.of([_mean(rounds[n - 1], "success") for rounds in done]) for n in UNTUNED_READ]
        best = [max(_mean(rows, "success") for rows in rounds) for rounds in done]
        floor = sum(_mean(rounds[-1], "success") >= ORACLE_FLOOR for rounds in done)
        cells = " | ".join(map(str, read))
        lines.append(f"| {agent} | {cells} | {SeedSummary.of(best)} | {floor} of {len(done)} |")
    header = [
        "",
        f"The untuned study's Unlock oracle (`{UNTUNED_FOLDER}/unlock-oracle.toml`: the env id and the image "
        f"view, every other setting the library's) under version {UNTUNED_VERSION} of the defaults, trained "
        f"{UNTUNED_ROUNDS} rounds, under the version's agent and under the presets' (`dqn`): success at a "
        "round, mean over seeds; its best round, each run's highest success at any round; and the runs whose "
        f"last round reached the untuned study's floor of {ORACLE_FLOOR}.",
        "",
        f"| agent | {' | '.join(f'round {n}' for n in UNTUNED_READ)} | its best round | at {ORACLE_FLOOR} |",
        f"|---|{'---|' * len(UNTUNED_READ)}---|---|",
    ]
    return [*header, *lines] if lines else []


def glance(runs: list[TrialRun]) -> Glance:
    """The oracle's success under patience 3 capped at :data:`CAP`, against the preset's 5 rounds."""
    rules = _rules(runs, "oracle")
    base, rule = rules[PRESET_LENGTH], rules[f"cap {CAP}, patience 3"]
    seeds = sorted(set(base) & set(rule))
    diff = SeedSummary.of([rule[s][0] - base[s][0] for s in seeds])
    headline = f"Unlock oracle success, cap {CAP} with patience 3 minus 5 rounds, paired: {diff}"
    return Glance(headline, EXPLORATORY)


STUDIES: dict[str, Study] = {
    "sizing": Study(
        (
            *(sweep for arm in ARMS for sweep in (_capped(arm), _five_rounds(arm))),
            *map(_variant, VARIANTS),
            _untuned(),
        ),
        tables,
        "Training sized to the task: rounds capped, stopped by the greedy evaluation's patience",
        "MiniGrid Unlock with the DoorKey presets (no preset sized for it)",
        glance,
        seeds=SEEDS,
        first_seed=FIRST_SEED,
    ),
}
