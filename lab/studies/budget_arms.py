"""What a label-budget run's arm is: the settings its sweep varies or sets (its grid's keys), in
words, and the short names a page's tables and figures call it by."""

from __future__ import annotations

from dospcot.sweeps.report import TrialRun
from dospcot_lab.studies.tables import FRACTION

STRATEGY = "training.label_strategy"
BUDGET = "training.label_budget"
SCHEDULE = "training.query_schedule"
FIRST_SHARE = "training.first_round_share"
FLOOR = "training.query_class_floor"
RANDOM_SHARE = "training.query_random_share"
REFIT = "cotraining.refit_new_classes"
QUOTA = "cotraining.quota"
ENDS = "env.episode_end_classes"
EXPLORATION = "training.exploration"
ADMIT = "cotraining.add_fraction_start"
REFIT_ARM = "refit on a new class"
"""The words of an arm name that say its classifiers refit when a class first showed."""
ENDS_ARM = "goal on episode ends only"
"""The words of an arm name that say its grid kept a class labelled only on episode ends there."""


def method_of(run: TrialRun) -> str:
    """A run's method from its preset's name: oracle, self-training, dospcot or reward-model."""
    config = run.trial.config
    for method in ("self-training", "reward-model", "oracle"):
        if config.endswith(f"-{method}"):
            return method
    return "dospcot"


def arm_of(run: TrialRun) -> str:
    """A run's arm: its method and the settings its sweep varies or sets, but for the label budget (the
    curves' x-axis) and the label fraction of a uniform mask (its budget)."""
    return " ".join(arm_parts(run))


def arm_parts(run: TrialRun) -> list[str]:
    """The words of :func:`arm_of`, one setting each: the method first, then the query strategy and
    the settings its sweep varies or sets."""
    params = run.trial.params
    method = method_of(run)
    if method == "oracle":
        return ["oracle"]
    parts = [method, params.get(STRATEGY, "uniform").strip('"')]  # a TOML string keeps its quotes
    if SCHEDULE in params:
        parts.append(params[SCHEDULE])
    if FIRST_SHARE in params:
        parts.append(f"round 1 <= {params[FIRST_SHARE]}")
    if FLOOR in params:
        parts.append(f"class floors {float(params[FLOOR]):.0%}")
    if RANDOM_SHARE in params:
        parts.append(f"{float(params[RANDOM_SHARE]):.0%} at random")
    if params.get(REFIT) == "true":
        parts.append(REFIT_ARM)
    if QUOTA in params:
        parts.append("quota " + params[QUOTA].strip('"'))
    if params.get(ENDS) == "true":
        parts.append(ENDS_ARM)
    if params.get(FRACTION) == "1.0":
        parts.append("every reward labelled")
    if EXPLORATION in params:
        parts.append(
            ROUNDS_ARM if params[EXPLORATION] == "rounds" else f"exploration by {params[EXPLORATION]}"
        )
    if ADMIT in params:
        parts.append(f"admitting {float(params[ADMIT]):.0%} of U in round 1")
    return parts


SHORT_NAME = 30
"""The longest arm name a table or figure shows (settings shortened by :data:`ABBREVIATIONS` first,
then a letter, its settings in a table under the task's tables)."""
ABBREVIATIONS = {
    "dospcot": "DOSPCoT",
    "self-training": "ST",
    "reward-model": "RM",
    "outcomes+disagreement": "o+d",
    "outcomes+uncertainty": "o+u",
    "disagreement": "dis",
    "uncertainty": "unc",
    REFIT_ARM: "refit",
    ENDS_ARM: "ends",
    "every reward labelled": "all labelled",
    "quota candidates": "quota",
}
"""Short words for the settings that make arm names long, said above each task's tables that use them."""


def short_names(arms: dict[str, list[TrialRun]]) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """What a task's tables and figure call each arm: the settings every arm but the oracle shares
    (said once, above the tables); per arm, its method and the settings left, in
    :data:`ABBREVIATIONS`' short words where the name is longer than :data:`SHORT_NAME` characters,
    and "arm A", "arm B", ... where it still is; and the short words used, with what they stand for."""
    parts = {arm: arm_parts(members[0]) for arm, members in arms.items()}
    others = [words for arm, words in parts.items() if arm != "oracle"]
    shared = [word for word in others[0][1:] if all(word in words[1:] for words in others)] if others else []
    names, used, letters = {}, {}, iter("ABCDEFGHIJKLMNOPQRSTUVWXYZ")
    for arm, words in parts.items():
        kept = [words[0], *(word for word in words[1:] if word not in shared)]
        name = " ".join(kept)
        if len(name) > SHORT_NAME:
            name = " ".join(ABBREVIATIONS.get(word, word) for word in kept)
            # DOSPCoT needs no gloss: only a short word that spells another is said.
            used.update(
                {ABBREVIATIONS[w]: w for w in kept if w in ABBREVIATIONS and ABBREVIATIONS[w].lower() != w}
            )
        names[arm] = name if len(name) <= SHORT_NAME else f"arm {next(letters)}"
    return shared, names, used


def by_arm(runs: list[TrialRun]) -> dict[str, list[TrialRun]]:
    """``runs`` by their arm (:func:`arm_of`), in the order the runs come."""
    arms: dict[str, list[TrialRun]] = {}
    for run in runs:
        arms.setdefault(arm_of(run), []).append(run)
    return arms


ROUNDS_ARM = "exploration by rounds"


def goal_on_ends(arm: str) -> str:
    """Arm ``arm``'s name where its grid also keeps the goal to episode ends (:data:`ENDS_ARM`, which
    :func:`arm_of` puts before the exploration's words)."""
    return arm.replace(ROUNDS_ARM, f"{ENDS_ARM} {ROUNDS_ARM}")
