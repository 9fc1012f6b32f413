"""The label-budget study, confirmatory: the settings the nine explorations chose, on seeds
100-109, grid16 layouts no study had used, both MiniGrid tasks, the fast highway and MiniGrid's
Unlock, which no one here had trained on, with the hypotheses B1-B4 of
docs/preregistration-budget.md. Its tables are :mod:`~dospcot_lab.studies.budget`'s, each task's
ending with the hypotheses it bears on."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dospcot.statistics import SeedSummary
from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.budget import (
    ENDS_ON,
    ORACLE_SHARE,
    OUTCOMES,
    REFIT_ON,
    budget_sweep,
    figure,
    paired_values,
    spend,
    task_tables,
)
from dospcot_lab.studies.budget_arms import BUDGET, REFIT_ARM, ROUNDS_ARM, by_arm, goal_on_ends
from dospcot_lab.studies.declaration import Glance, Study, Sweep
from dospcot_lab.studies.grid_studies import LAYOUT
from dospcot_lab.studies.tables import labels_cell, labels_used

FIRST_SEED, SEEDS = 100, 10
GRID_LAYOUTS = ("404", "505", "606")
"""grid16 layouts no study had used (the record's: 0, 1, 3, 4, 11, 101, 202 and 303)."""
UNLOCK = {"gym.env_id": ('"minigrid:MiniGrid-Unlock-v0"',), "gym.episode_steps": ("288",)}
"""B4's task: MiniGrid-Unlock-v0 (pick up the key, open the locked door; 288 steps, its own limit)
under the DoorKey presets, unchanged but for the env and its episode length."""

LABELS = {"grid16": "20", "doorkey": "100", "lavagap": "100", "fasthighway": "400", "unlock": "100"}
"""The budget named per task: on MiniGrid (Unlock included) the explorations'; on grid16 and the fast
highway about what one agent's 2% mask revealed in the active-queries study."""
SECOND = "200"
"""B3's second DOSPCoT budget; the blind control buys twice each of DOSPCoT's."""

SCHEDULE = "decay"
"""The schedule named for every arm but B1's reference, which spends at once (``"asap"``)."""
DOSPCOT = f"dospcot outcomes+disagreement {SCHEDULE} {REFIT_ARM} {ROUNDS_ARM}"
ASAP = f"dospcot outcomes+disagreement asap {REFIT_ARM} {ROUNDS_ARM}"
SELF_TRAINING = f"self-training uncertainty {SCHEDULE} {REFIT_ARM} {ROUNDS_ARM}"
REWARD_MODEL = f"reward-model disagreement {SCHEDULE} {ROUNDS_ARM}"
BLIND = f"dospcot random {SCHEDULE} {REFIT_ARM} {ROUNDS_ARM}"
FIGURE = "![success against labels used, per arm, and the oracle's](budget.png)"


GOAL_ON_ENDS = frozenset({"grid16"})
"""The keys of :data:`LABELS` whose arms keep the goal to episode ends by a key of their sweep
(``env.episode_end_classes``); the MiniGrid presets do so by their own ``gym.episode_end_classes``."""


def _on(key: str, arm: str) -> str:
    """Arm ``arm``'s name on the task of key ``key`` (:data:`GOAL_ON_ENDS`)."""
    return goal_on_ends(arm) if key in GOAL_ON_ENDS else arm


def _sweep(task: str, name: str, preset: str, grid: dict[str, tuple[str, ...]]) -> Sweep:
    """A sweep of the study: every arm that co-trains (DOSPCoT's and self-training's) refits its
    classifiers when a class first shows (the reward-model peer fits on the labels alone every round),
    and every arm of a task in :data:`GOAL_ON_ENDS` keeps the goal to episode ends."""
    settings = {**grid, **(ENDS_ON if task in GOAL_ON_ENDS else {})}
    if not preset.endswith(("-oracle", "-reward-model")):
        settings.update(REFIT_ON)
    return budget_sweep(f"budget-confirm-{task}-{name}", preset, settings)


def _peers(task: str, prefix: str, grid: dict[str, tuple[str, ...]]) -> tuple[Sweep, ...]:
    """B2's arms on a task: DOSPCoT, self-training with uncertainty and the reward-model peer with
    disagreement, each at the task's budget on :data:`SCHEDULE`."""
    labels = LABELS[task]
    return (
        _sweep(task, "dospcot", f"{prefix}-dospcot", {**grid, **spend(OUTCOMES, SCHEDULE, labels)}),
        _sweep(
            task,
            "self-training",
            f"{prefix}-self-training",
            {**grid, **spend("uncertainty", SCHEDULE, labels)},
        ),
        _sweep(
            task,
            "reward-model",
            f"{prefix}-reward-model",
            {**grid, **spend("disagreement", SCHEDULE, labels)},
        ),
    )


def _minigrid(task: str) -> tuple[Sweep, ...]:
    prefix = f"minigrid-{task}"
    return (
        _sweep(task, "oracle", f"{prefix}-oracle", {}),
        *_peers(task, prefix, {}),
        _sweep(task, "asap", f"{prefix}-dospcot", spend(OUTCOMES, "asap")),
        _sweep(task, "dospcot-200", f"{prefix}-dospcot", spend(OUTCOMES, SCHEDULE, SECOND)),
        _sweep(task, "random", f"{prefix}-dospcot", spend("random", SCHEDULE, "200", "400")),
    )


# DoorKey first, whose runs take the least time, then the rest of the hypotheses' arms.
SWEEPS = (
    *_minigrid("doorkey"),
    *_minigrid("lavagap"),
    *_peers("grid16", "grid16", {LAYOUT: GRID_LAYOUTS}),
    _sweep("fasthighway", "oracle", "fasthighway-oracle", {}),
    *_peers("fasthighway", "fasthighway", {}),
    _sweep("unlock", "oracle", "minigrid-doorkey-oracle", UNLOCK),
    _sweep("unlock", "dospcot", "minigrid-doorkey-dospcot", {**UNLOCK, **spend(OUTCOMES, SCHEDULE)}),
)
"""Every arm explores by the share of rounds done, draws from its agents' own generators and trains
under numerics 2 (:func:`~dospcot_lab.studies.budget.budget_sweep`)."""


def _is_unlock(run: TrialRun) -> bool:
    return "gym.env_id" in run.trial.params


def _of(prefix: str) -> Callable[[TrialRun], bool]:
    return lambda run: run.trial.config.startswith(prefix) and not _is_unlock(run)


TASKS = {
    "grid16, layouts 404, 505, 606": ("grid16", _of("grid16-")),
    "MiniGrid-DoorKey-5x5-v0": ("doorkey", _of("minigrid-doorkey-")),
    "MiniGrid-LavaGapS7-v0": ("lavagap", _of("minigrid-lavagap-")),
    "fast highway": ("fasthighway", _of("fasthighway-")),
    "MiniGrid-Unlock-v0": ("unlock", _is_unlock),
}
"""Each task's title, its key in :data:`LABELS` and whether a run belongs to it."""
TASKS_BY_KEY = {key: belongs for key, belongs in TASKS.values()}
MINIGRID = ("doorkey", "lavagap")
"""The keys of the MiniGrid tasks B1 pools and B3 reads."""
PAIRS = {"grid16": SEEDS * len(GRID_LAYOUTS)}
"""The pairs a comparison on a task holds once run (by seed, and layout on the grid)."""


def _at(arms: dict[str, list[TrialRun]], arm: str, labels: str) -> list[TrialRun]:
    return [r for r in arms.get(arm, []) if r.trial.params.get(BUDGET) == labels]


def _unequal(first: list[TrialRun], second: list[TrialRun]) -> str:
    """A warning where two arms' mean labels used lie more than 2% apart: their budget was not equal
    (none while either arm has no run to count)."""
    if not first or not second:
        return ""
    a, b = (float(np.mean([labels_used(r) for r in runs])) for runs in (first, second))
    return " (labels unequal: more than 2% apart)" if abs(a - b) > 0.02 * max(a, b) else ""


def _verdict(held: bool | None) -> str:
    return "not decided yet" if held is None else "**held**" if held else "**not met**"


def _versus(arms: dict[str, list[TrialRun]], task: str, b: str) -> tuple[SeedSummary, bool | None]:
    """Success of DOSPCoT minus arm ``b`` at the task's budget, paired, and whether its interval lies
    above 0 (None until every pair has run)."""
    labels = LABELS[task]
    values = paired_values(_at(arms, _on(task, DOSPCOT), labels), _at(arms, _on(task, b), labels))
    diff = SeedSummary.of(values)
    return diff, None if len(values) < PAIRS.get(task, SEEDS) else diff.low > 0


def _b1_values(runs: list[TrialRun]) -> list[float]:
    """B1's pairs: DOSPCoT on :data:`SCHEDULE` minus spending at once, at 100 labels, both MiniGrid
    tasks pooled."""
    values = []
    for key in MINIGRID:
        arms = by_arm([r for r in runs if TASKS_BY_KEY[key](r)])
        values += paired_values(_at(arms, DOSPCOT, "100"), _at(arms, ASAP, "100"))
    return values


def _b1(runs: list[TrialRun]) -> tuple[SeedSummary, bool | None, str]:
    """B1's difference, its verdict (None until all 20 pairs have run) and any warning that its arms'
    labels were unequal."""
    values = _b1_values(runs)
    diff = SeedSummary.of(values)
    arms = [by_arm([r for r in runs if TASKS_BY_KEY[key](r)]) for key in MINIGRID]
    unequal = _unequal(*([r for a in arms for r in _at(a, arm, "100")] for arm in (DOSPCOT, ASAP)))
    return diff, None if len(values) < 2 * SEEDS else diff.low > 0, unequal


def _b2(runs: list[TrialRun]) -> tuple[int, bool | None]:
    """The tasks where DOSPCoT beat both peers (both intervals above 0), and B2's verdict: held as soon
    as two of the four tasks count (more pairs cannot undo it), not met only once every pair of every
    task has run."""
    won, decided = 0, True
    for key in ("grid16", "doorkey", "lavagap", "fasthighway"):
        arms = by_arm([r for r in runs if TASKS_BY_KEY[key](r)])
        verdicts = [_versus(arms, key, peer)[1] for peer in (SELF_TRAINING, REWARD_MODEL)]
        won += all(verdicts)
        decided &= None not in verdicts
    return won, (won >= 2) if (decided or won >= 2) else None


def _mean(runs: list[TrialRun]) -> float | None:
    return SeedSummary.of([r.summary["mean"]["success"] for r in runs]).mean if len(runs) == SEEDS else None


def _b3(arms: dict[str, list[TrialRun]]) -> tuple[str, bool | None]:
    """Whether DOSPCoT's mean success reaches 90% of the oracle's at a budget b (100 or 200) where the
    blind control's at 2b does not: DOSPCoT then needs at most b labels and the control more than 2b."""
    oracle = _mean(arms.get("oracle", []))
    if oracle is None:
        return "the oracle has not run every seed yet", None
    target = ORACLE_SHARE * oracle
    parts, held, decided = [], False, True
    for budget in ("100", SECOND):
        mine, blind = _mean(_at(arms, DOSPCOT, budget)), _mean(_at(arms, BLIND, str(2 * int(budget))))
        if mine is None or blind is None:
            decided = False
            continue
        parts.append(
            f"DOSPCoT at {budget} labels {mine:.3f}, the blind control at {2 * int(budget)} {blind:.3f}"
        )
        held |= mine >= target > blind
    text = f"target {target:.3f}; " + ("; ".join(parts) or "no budget run yet")
    return text, held if held or decided else None


def _b4(arms: dict[str, list[TrialRun]]) -> tuple[str, str]:
    """B4's line on Unlock and its verdict in words: held, not met, not testable or not decided yet."""
    oracle, mine = _mean(arms.get("oracle", [])), _mean(_at(arms, DOSPCOT, LABELS["unlock"]))
    if oracle is None or mine is None:
        return f"- B4 (Unlock): {_verdict(None)}.", _verdict(None)
    figures = f"DOSPCoT at {LABELS['unlock']} labels {mine:.3f}, the oracle {oracle:.3f}"
    if oracle < 0.5:
        return f"- B4 (Unlock): {figures}; the oracle is below 0.5, so B4 is not testable.", "not testable"
    share = mine / oracle
    verdict = _verdict(share >= 0.8)
    return f"- B4 (Unlock): {figures}, {share:.1%} of it; at least 80%: {verdict}.", verdict.strip("*")


def _hypotheses(key: str, arms: dict[str, list[TrialRun]]) -> list[str]:
    """The hypotheses' lines that bear on task ``key``."""
    if key == "unlock":
        return [_b4(arms)[0]]
    lines = []
    for name, peer in (
        ("self-training with uncertainty", SELF_TRAINING),
        ("the reward-model peer", REWARD_MODEL),
    ):
        diff, held = _versus(arms, key, peer)
        mine, theirs = (labels_cell(_at(arms, _on(key, arm), LABELS[key])) for arm in (DOSPCOT, peer))
        unequal = _unequal(*(_at(arms, _on(key, arm), LABELS[key]) for arm in (DOSPCOT, peer)))
        lines.append(
            f"- B2 ({key}): success of DOSPCoT minus {name}, paired: {diff} over {diff.n} pairs ({mine} "
            f"against {theirs} labels a run{unequal}); interval above 0: {_verdict(held)}."
        )
    if key in MINIGRID:
        text, held = _b3(arms)
        reach = "DOSPCoT reaches it where the control at twice its labels does not"
        lines.append(f"- B3 ({key}): {text}; {reach}: {_verdict(held)}.")
    return lines


def _tables(runs: list[TrialRun]) -> list[str]:
    b1, b1_held, unequal = _b1(runs)
    won, b2_held = _b2(runs)
    lines = [
        f"Confirmatory: seeds {FIRST_SEED}-{FIRST_SEED + SEEDS - 1}, registered in "
        "docs/preregistration-budget.md before its runs; each agent draws from its own generators, "
        "numerics 2. An arm names its method, label strategy and schedule; labels used counts the "
        "labels each run held at its end. Differences are paired by seed, and layout on the grid.",
        *(["", FIGURE] if set(by_arm(runs)) - {"oracle"} else []),
        "",
        f"- B1 (MiniGrid, pooled): success of DOSPCoT's {SCHEDULE} schedule minus asap at 100 labels, "
        f"paired: {b1} over {b1.n} pairs{unequal}; interval above 0: {_verdict(b1_held)}.",
        f"- B2: DOSPCoT beat both peers on {won} of 4 tasks; at least two: {_verdict(b2_held)}.",
        f"- B3: held on both MiniGrid tasks: {_verdict(_b3_both(runs))}.",
    ]
    for task, (key, belongs) in TASKS.items():
        arms = by_arm([r for r in runs if belongs(r)])
        if arms:
            lines += task_tables(task, arms, ["Hypotheses:", "", *_hypotheses(key, arms)])
    return lines


def _b3_both(runs: list[TrialRun]) -> bool | None:
    verdicts = [_b3(by_arm([r for r in runs if TASKS_BY_KEY[key](r)]))[1] for key in MINIGRID]
    if False in verdicts:
        return False
    return None if None in verdicts else True


def _glance(runs: list[TrialRun]) -> Glance:
    b1, b1_held, _ = _b1(runs)
    won, b2_held = _b2(runs)
    b4 = _b4(by_arm([r for r in runs if _is_unlock(r)]))[1]
    verdicts = [
        f"B1: {_verdict(b1_held).strip('*')}",
        f"B2: {_verdict(b2_held).strip('*')} ({won} of 4 tasks)",
        f"B3: {_verdict(_b3_both(runs)).strip('*')}",
        f"B4: {b4}",
    ]
    return Glance(
        f"MiniGrid success, 100 labels on the {SCHEDULE} schedule minus spent at once, paired: {b1}",
        "; ".join(verdicts),
    )


STUDIES: dict[str, Study] = {
    "budget": Study(
        SWEEPS,
        _tables,
        "Labels that pay: a label budget spread over training, against the peers (confirmatory)",
        "grid16 (unseen layouts), MiniGrid DoorKey, LavaGap and Unlock, the fast highway",
        _glance,
        seeds=SEEDS,
        first_seed=FIRST_SEED,
        figure=figure({task: belongs for task, (_, belongs) in TASKS.items()}),
        confirmatory=True,
    ),
}
