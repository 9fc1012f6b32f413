"""Versions of the defaults: a config names the version of the defaults it was written against
(``defaults = N``), so a default can move without restating what an older config, run folder or sweep
meant.

A config without the key gets :data:`ADOPTED`. Each version after 1 builds on an earlier one
(:data:`BASES`) and lists the keys whose default it moves there (:class:`MovedDefault`); a key the
config sets itself keeps its value whatever the version. A version's rule may depend on the config's
method and views (a strategy that asks where two views disagree needs two views), and a rule that
returns None leaves the key at the earlier default.

Version 3, adopted before version 12, is version 1 with the reward classifiers fitted under numerics 2,
which the numerics study showed non-inferior on both of its presets (docs/results/numerics.md). Version 2
is a **candidate**, built on version 1: the settings under which the label-budget study's DOSPCoT reached
90% of the oracle on DoorKey and LavaGap and carried to a MiniGrid task no preset was tuned on. The
defaults study did not show it non-inferior on grid16 (docs/guide/defaults.md), so ``defaults = 2`` opts
in. Version 4, a candidate, is version 3 with exploration by rounds: an agent's exploration falls with
the share of rounds done, where under the pace it reached its floor as soon as the co-trainer had
admitted the pool (after a round or two); on LavaGap the true-rewards study found that this costs
co-trained agents part of what the oracle learns from the same rewards. The defaults-4 study did not show
it non-inferior on grid16, so ``defaults = 4`` opts in. Version 5, a candidate, is version 3 with each
round's co-training in four passes (``training.cotrain_passes``), so a step the agents take is rewarded
in their replay a quarter of a round later rather than a round later: the true-rewards study traced much
of the co-training path's loss on MiniGrid to that lag. The defaults-5 study did not show it non-inferior
on grid16, so ``defaults = 5`` opts in. Version 6, a candidate, is version 5 with the refit on a new
class (``cotraining.refit_new_classes``): a pass early in round 1 fits the classifiers on the labels
alone before every class has shown, and without the refit a class first labelled later is never fitted
that way (grid16's lava, on the first seed of the defaults-5 study). The defaults-6 study did not show it
non-inferior on grid16, so ``defaults = 6`` opts in. Version 7, a candidate, is version 6 with the passes
from round 2 (``training.passes_from_round``): under versions 5 and 6 a sparse task's first pass came
before any goal label, so every step it admitted read the common class's reward, and the agents learned
that the task pays nothing; round 1 now co-trains once, as under version 3. The defaults-7 study held it
non-inferior on grid16 but not on DoorKey, so ``defaults = 7`` opts in. Version 8, a candidate, is
version 7 with exploration by rounds: under the pace DoorKey's agents reached their exploration floor
after round 1, as soon as the pool was admitted, and there the co-training path fed the true rewards
matched the oracle only where its passes came with exploration by rounds (the true-rewards study). The
defaults-8 study did not show it non-inferior on grid16, so ``defaults = 8`` opts in. Version 9, a
candidate, is version 3 with the MiniGrid presets' length and agents' settings for a gym task (``task =
"gym"``) that sets none of its own: rounds of 10,000 steps, a discount of 0.9, 3-step windows,
exploration from 0.5, an update every 2 steps and a target network moved every 250 (the settings tuned on
LavaGap that carried to DoorKey), and exploring starts in training (``ReachableStart``) on a MiniGrid
env. Under version 3 the untuned study's oracle, fed every reward, reached 0.8 success on none of its
five MiniGrid tasks; the presets set every one of these keys, so version 9 trains each of them as version
3 does. Version 10, a candidate, is version 9 with version 2's queries (a budget of 100 labels bought by
``outcomes+disagreement`` on a decaying schedule, each agent its own draws, exploration by rounds, the
refit): under version 9 a co-trained run's 5% mask holds thousands of labels, over the 100 issue 78
allows. Version 11, a candidate, is version 10 with version 5's and version 7's passes (four co-training
passes a round, from round 2): under version 10 the untuned study's DOSPCoT on DistShift1 ended with
every goal step pseudo-rewarded right and still reached the goal in an eighth of the oracle's episodes,
where the true-rewards study had traced such a loss to the round's lag. Version 12, adopted before
version 13, is version 10 with ten score passes a round for DOSPCoT (``training.pass_kind = "score"``): a
pass refits nothing, so it costs a forward pass of each classifier where version 11's refits took most of
a round on MiniGrid's egocentric map, and the true-rewards study's control with such passes matched the
oracle on DoorKey. The defaults-12 study held it non-inferior to version 3 on both presets
(docs/results/defaults-12.md). Version 13, adopted before version 14, is version 12 with the steps'
reward in a class of its own on a gym task (``gym.step_class``): under queries on episode ends a MiniGrid
goal paid by its time could share the steps' quantile class, which then paid every step part of a goal
(docs/results/step-class.md). The defaults-13-same-cpu study held it non-inferior to version 12 on both
presets (docs/results/defaults-13-same-cpu.md). Version 14, **adopted**, is version 13 with round 1's
labels bought and fitted at round 1's first pass (``training.first_labels = "first_pass"``) for DOSPCoT:
under version 13 no step of round 1 was rewarded before the round's end, and the true-rewards study's
control, fed the true rewards, ended round 1 on DoorKey without a success where the oracle had most of
its own. The defaults-14 study held it non-inferior to version 13 on both presets
(docs/results/defaults-14.md). Nothing here imports torch."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from dospcot.config.choices import DEFAULT_VIEWS, method_name
from dospcot.config.learning_sections import CoTrainingConfig, TrainingConfig

TaskSection = tuple[str, type]
"""A config's task section: its name (``env``, ``gym``, ``highway``) and its dataclass."""

ADOPTED = 14
"""The version of the defaults a config without ``defaults`` gets."""

FIRST = 1
"""The version every config, run folder and sweep written before versions existed was written against."""

REWARD_LEARNERS = ("dospcot", "reward-model")
"""The methods whose classifiers reward unlabelled samples, and so may query a rater."""

PASSES = 4
"""Version 5's co-training passes a round (``training.cotrain_passes``): the true-rewards study's short
rounds cut the lag by as much."""

SCORE_PASSES = 10
"""Version 12's passes a round, score passes (``training.pass_kind = "score"``): the true-rewards
study's arm that matched the oracle on DoorKey."""

GYM_SETTINGS: dict[str, Any] = {
    "training.steps_per_round": 10_000,
    "dqn.gamma": 0.9,
    "dqn.n_steps": 3,
    "dqn.train_freq": 2,
    "dqn.target_update_interval": 250,
    "training.eps_start": 0.5,
}
"""Version 9's settings for a gym task: the length and the agents' settings the MiniGrid presets share
(tuned on LavaGap)."""

EXPLORING_STARTS = "dospcot.envs.minigrid_views:ReachableStart"
"""Version 9's training wrapper on a MiniGrid env: each training episode starts on a random empty cell
that the task's start connects to."""

BUDGET = 100
"""Version 2's label budget: the answers a run may buy, whatever its length (lowered to the samples a
short run meets, :func:`dospcot.config.version_defaults.fit_budget`)."""


@dataclass(frozen=True)
class MovedDefault:
    """One key whose default a version moves.

    :param key: the dotted key (``training.exploration``); ``{section}`` stands for the config's task
        section (``env``, ``gym``, ...), where the task's section has the key.
    :param value: the version's default for a config table (its method, views, task), or None where the
        key keeps the earlier version's default for that config.
    :param why: the study of the record that supports the move, in a few words.
    :param sections: the task sections (``gym``, ...) of the configs the move applies to; None: every
        config's.
    """

    key: str
    value: Callable[[Mapping[str, Any]], Any]
    why: str
    sections: tuple[str, ...] | None = None


def _method(table: Mapping[str, Any]) -> str:
    return method_name(str(table.get("method", "dospcot")))


def _learns_rewards(table: Mapping[str, Any]) -> bool:
    return _method(table) in REWARD_LEARNERS


def _learns_single_rewards(table: Mapping[str, Any]) -> bool:
    """Whether the run learns rewards from labels of single steps, not of segments."""
    segments = _section(table, "training").get("segment_length", TrainingConfig.segment_length)
    return _learns_rewards(table) and not (_whole(segments) and segments > 1)


def _strategy(table: Mapping[str, Any]) -> str | None:
    """Episode ends first, then where the views (or the reward model's members) disagree; a run with one
    classifier asks where it is least sure instead. None for a run that asks no rater: one that learns
    no reward, learns from segment labels, or has no view (the config's own check names that)."""
    if not _learns_single_rewards(table):
        return None
    views = table.get("views", DEFAULT_VIEWS)
    classifiers = len(views) if isinstance(views, list | tuple) else 1
    if classifiers == 0:
        return None
    if _method(table) == "reward-model":
        size = _section(table, "cotraining").get("ensemble_size", CoTrainingConfig.ensemble_size)
        classifiers *= size if _whole(size) else CoTrainingConfig.ensemble_size
    return "outcomes+disagreement" if classifiers >= 2 else "outcomes+uncertainty"


def _when_learning(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    return lambda table: value if _learns_rewards(table) else None


def _when_learning_single_rewards(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    return lambda table: value if _learns_single_rewards(table) else None


def _when_asking(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    """``value`` for a run whose strategy, its own or the version's, asks a rater."""

    def rule(table: Mapping[str, Any]) -> Any:
        strategy = _section(table, "training").get("label_strategy") or _strategy(table)
        return value if strategy not in (None, "uniform") else None

    return rule


def _when_buying(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    """``value`` for a run that asks a rater (:func:`_when_asking`) and buys a budget counted in labels:
    not one that sets ``training.label_budget = 0`` itself, whose budget is its label share."""
    asking = _when_asking(value)

    def rule(table: Mapping[str, Any]) -> Any:
        return None if _section(table, "training").get("label_budget") == 0 else asking(table)

    return rule


def _without_labelled_demonstrations(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    """``value`` for a run that learns rewards and takes no demonstrations as labels: they do not record
    which of their steps ended an episode."""

    def rule(table: Mapping[str, Any]) -> Any:
        demos = _section(table, "demonstrations")
        labelled = (demos.get("file") or demos.get("agent")) and demos.get("labels", True)
        return value if _learns_rewards(table) and not labelled else None

    return rule


def _passes(count: int, methods: tuple[str, ...] = REWARD_LEARNERS) -> Callable[[Mapping[str, Any]], Any]:
    """``count`` passes a round (at most a round's steps) for a run of ``methods`` that learns single
    rewards; None for any other run, or one that learns from segment labels (co-trained once a round)."""

    def rule(table: Mapping[str, Any]) -> int | None:
        if _method(table) not in methods or not _learns_single_rewards(table):
            return None
        steps = _section(table, "training").get("steps_per_round", TrainingConfig.steps_per_round)
        return min(count, steps) if _whole(steps) and steps >= 1 else count

    return rule


SCORE_PASS_METHODS = ("dospcot",)
"""The methods version 12 gives score passes: DOSPCoT, the method the defaults-12 study measured. The
reward-model peer takes them only where its config sets them (the views study does, so that every arm
is rewarded with the same lag)."""


def _when_co_training(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    """``value`` for a run of :data:`SCORE_PASS_METHODS` that learns single rewards."""
    return lambda table: (
        value if _method(table) in SCORE_PASS_METHODS and _learns_single_rewards(table) else None
    )


GYM = ("gym",)
"""Version 9's task sections: the gym task's, the task a user's own env is (the grid and the highway
keep what their presets tune)."""


def _exploring_starts(table: Mapping[str, Any]) -> list[str] | None:
    """:data:`EXPLORING_STARTS` for an env of MiniGrid's (an id ``MiniGrid-...``, with or without the
    ``minigrid:`` prefix that imports it), whose random walks from the task's start seldom reach a
    distant goal; None for any other env."""
    env_id = _section(table, "gym").get("env_id", "")
    if not isinstance(env_id, str):
        return None
    return [EXPLORING_STARTS] if env_id.rpartition(":")[2].startswith("MiniGrid-") else None


def _constant(value: Any) -> Callable[[Mapping[str, Any]], Any]:
    return lambda table: value


def _whole(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _section(table: Mapping[str, Any], name: str) -> Mapping[str, Any]:
    """``table``'s section ``name``; empty where it is missing or not a table. A rule reads only what
    it can: the config's own check names anything wrong with the values it skips."""
    part = table.get(name, {})
    return part if isinstance(part, Mapping) else {}


QUERY_MOVES = (
    MovedDefault(
        "training.exploration",
        lambda table: "rounds",
        "budget study: exploration by rounds, not by the pace of pseudo-rewards",
    ),
    MovedDefault("training.agent_draws", lambda table: "own", "budget study: each agent its own draws"),
    MovedDefault("training.label_strategy", _strategy, "budget study: outcomes+disagreement"),
    MovedDefault("training.query_schedule", _when_buying("decay"), "budget study: a decaying schedule"),
    MovedDefault(
        "training.query_end_states", _when_asking("spread"), "episode ends spread over their end states"
    ),
    MovedDefault("training.label_budget", _when_asking(BUDGET), "budget study: 100 labels"),
    MovedDefault(
        "cotraining.refit_new_classes", _when_learning(True), "budget study: the refit on a new class"
    ),
    MovedDefault(
        "{section}.episode_end_classes",
        _without_labelled_demonstrations(True),
        "budget study: the goal's class kept to episode ends",
    ),
)
"""Version 2's moves (and version 10's): the label-budget study's queries and the settings they
came with."""

PASSES_MOVE = MovedDefault(
    "training.cotrain_passes",
    _passes(PASSES),
    "true-rewards study: a step rewarded a part of a round after it is taken, not a round",
)
"""Version 5's move (and version 11's): :data:`PASSES` co-training passes a round."""

LATER_PASSES_MOVE = MovedDefault(
    "training.passes_from_round",
    _when_learning_single_rewards(2),
    "defaults-6 study: a sparse task's first pass came before its goal's first label",
)
"""Version 7's move (and version 11's): the passes from round 2, so round 1 co-trains once."""

SCORE_PASS_MOVES = (
    MovedDefault(
        "training.cotrain_passes",
        _passes(SCORE_PASSES, SCORE_PASS_METHODS),
        "true-rewards study: ten score passes a round matched the oracle on DoorKey",
    ),
    MovedDefault(
        "training.pass_kind",
        _when_co_training("score"),
        "true-rewards study: a pass scores the steps since with the classifiers as they are, fitting none",
    ),
)
"""Version 12's moves: :data:`SCORE_PASSES` score passes a round."""


def _early_labels(table: Mapping[str, Any]) -> str | None:
    """``"first_pass"`` for a run of :data:`SCORE_PASS_METHODS` that learns single rewards, whose round 1
    comes in passes (its own ``cotrain_passes`` of 2 or more, else version 12's, from round 1) and whose
    rater is simulated; None for any other run (``training.first_labels`` needs all three)."""
    training = _section(table, "training")
    passes = training.get("cotrain_passes", _passes(SCORE_PASSES, SCORE_PASS_METHODS)(table))
    in_parts = _whole(passes) and passes >= 2 and training.get("passes_from_round", 1) == 1
    simulated = training.get("rater", "simulated") == "simulated"
    return _when_co_training("first_pass")(table) if in_parts and simulated else None


VERSIONS: dict[int, tuple[MovedDefault, ...]] = {
    1: (),
    2: QUERY_MOVES,
    3: (
        MovedDefault(
            "cotraining.numerics",
            lambda table: 2,
            "numerics study: float32 fits over the samples that carry weight, non-inferior on both presets",
        ),
    ),
    4: (
        MovedDefault(
            "training.exploration",
            lambda table: "rounds",
            "true-rewards study: exploration by rounds, where the pace ended it once the pool was admitted",
        ),
    ),
    5: (PASSES_MOVE,),
    6: (
        MovedDefault(
            "cotraining.refit_new_classes",
            _when_learning(True),
            "defaults-5 study: a pass fits before every class has a label; the refit on a new class",
        ),
    ),
    7: (LATER_PASSES_MOVE,),
    8: (
        MovedDefault(
            "training.exploration",
            lambda table: "rounds",
            "true-rewards study: DoorKey's path matched the oracle with passes and exploration by rounds",
        ),
    ),
    9: (
        *(
            MovedDefault(key, _constant(value), "untuned study: the MiniGrid presets' settings", GYM)
            for key, value in GYM_SETTINGS.items()
        ),
        MovedDefault(
            "gym.train_wrappers",
            _exploring_starts,
            "untuned study: exploring starts in training on MiniGrid, where the oracle missed a far goal",
            GYM,
        ),
    ),
    10: QUERY_MOVES,
    11: (PASSES_MOVE, LATER_PASSES_MOVE),
    12: SCORE_PASS_MOVES,
    13: (
        MovedDefault(
            "gym.step_class",
            _when_learning(True),
            "step-class study: the steps' reward kept out of a late goal's class at a few labels",
            GYM,
        ),
    ),
    14: (
        MovedDefault(
            "training.first_labels",
            _early_labels,
            "true-rewards study: round 1's labels bought at its first pass, so its later steps are rewarded",
        ),
    ),
}
"""Each version's moved defaults, on top of the version it builds on (:data:`BASES`)."""

BASES = {2: 1, 3: 1, 4: 3, 5: 3, 6: 5, 7: 6, 8: 7, 9: 3, 10: 9, 11: 10, 12: 10, 13: 12, 14: 13}
"""The version each later version builds on: its defaults are that version's, then its own moves."""

CANDIDATES = frozenset({2, 4, 5, 6, 7, 8, 9, 10, 11})
"""Versions a config may opt into that no study has adopted yet."""
