"""The sections that set up the learning: ``[training]`` (the rounds and the labels), and
``[cotraining]`` with ``[cotraining.classifier]`` (the self-paced co-trainer and its reward classifiers).
The agents' sections are in :mod:`dospcot.config.agent_sections`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from dospcot.config.checks import check_at_least, check_label_fraction, check_positive, check_within
from dospcot.config.choices import (
    LOSS_KINDS,
    MODEL_KINDS,
    NUMERICS_VERSIONS,
    PSEUDO_REWARDS,
    QUERY_SCHEDULES,
    QUOTAS,
    WEIGHTINGS,
    AgentDraws,
    EndStateQueries,
    FirstLabels,
    LabelStrategy,
    LossKind,
    ModelKind,
    PassKind,
    PseudoRewards,
    QuerySchedule,
    Quota,
    Weighting,
)


class AddedKeys:
    """A config section whose keys outlive its run folders: ``added_keys`` names each key added since
    folders were first written, with the value a folder (or a pickled checkpoint) written before it
    ran under, so that a change of the key's default never restates what an old run did."""

    added_keys: ClassVar[dict[str, Any]] = {}

    def __setstate__(self, state: dict[str, Any]) -> None:
        # A checkpoint pickled before a key was added would otherwise read today's default.
        self.__dict__.update({**self.added_keys, **state})


@dataclass(frozen=True)
class TrainingConfig(AddedKeys):
    """The rounds of one run: the ``[training]`` section of a config, and the first fields of
    :class:`~dospcot.config.run_configs.TrainConfig`.

    :param rounds: co-training rounds.
    :param steps_per_round: env steps each agent takes per round.
    :param label_fraction: share of (s, a) keys whose reward is revealed, in (0, 1].
    :param eps_start: exploration at pace 0.
    :param eps_end: exploration at pace 1.
    :param exploration: what sets the pace that moves exploration from ``eps_start`` to ``eps_end``
        after each round. ``"pace"``: a co-trained run's admitted share of U (a fast self-paced
        schedule ends exploration after a round or two), baselines the share of rounds done.
        ``"rounds"``: the share of rounds done for every method, so co-trained agents and baselines
        explore alike.
    :param cotrain_passes: co-training passes per round (co-training and the reward-model peer). 1: the
        round collects ``steps_per_round`` steps, then co-trains. c > 1: the collection is cut into c
        equal parts and every part but the last is followed by a pass of the co-trainer that writes the
        reward table, so a step the agents take is rewarded in their replay within a part rather than a
        round; the self-paced schedule ages by 1/c per pass, so it admits what it would by the round's
        end. Labels are bought, the policy updated, exploration aged and the agents evaluated once a
        round, as under 1, and the co-trainer's stopping rules read a round's last pass. A pass early
        in round 1 may come before a rare class (a sparse task's goal) has a label: the steps it admits
        then all read the common class's reward (docs/results/defaults-6.md).
    :param passes_from_round: the first round (1-based) co-trained in ``cotrain_passes`` passes; the
        rounds before it co-train once, after their whole collection. 2: round 1's labels are all bought
        before the classifiers first admit a sample, so a sparse task's first goal label is not
        outrun by a pass. The self-paced schedule ages by one round per round either way.
    :param pass_kind: what each pass but a round's last does. ``"cotrain"``: the co-trainer's step, as
        described under ``cotrain_passes``. ``"score"``: no fit and no step of the schedule; the
        classifiers as the round's last co-training left them pseudo-reward the steps it did not admit,
        each view admitting at the least score it admitted each class at then
        (:mod:`dospcot.core.score_passes`), so a pass costs a forward pass of each classifier rather
        than a fit over the pool. A pass before the run's first co-training, or after a class has
        appeared or merged since the last, admits nothing. The reward-model peer's pass rewards the
        samples met since its last fit with its ensembles as they are
        (:meth:`~dospcot.core.reward_model.RewardModelTrainer.score`).
    :param first_labels: when a run that learns rewards first co-trains. ``"round_end"``: after round
        1's whole collection, so no step of round 1 is rewarded before the round's policy update.
        ``"first_pass"``: at round 1's first pass (round 1 in ``cotrain_passes`` > 1 parts, so
        ``passes_from_round = 1``): round 1's labels are bought there (its whole allowance, among the
        samples met by then) and the co-trainer fits them and writes the reward table, so the passes
        after it reward round 1's steps as they do a later round's; round 1's end buys what its
        allowance has left and co-trains as always. Under score passes the early co-training does not
        age the self-paced schedule; under co-training passes (``pass_kind = "cotrain"``) it is the
        pass's own step. The simulated rater only: a person's answers cannot pause a round's collection.
    :param update_steps: gradient steps each agent takes at the end of every round, after the
        co-trainer wrote that round's pseudo-rewards and before the agents are evaluated (the policy
        update), so the last round's pseudo-rewards are learned too; 0: none.
    :param learn_from_round: the first round (1-based) in which agents learn while they collect:
        before it they act uniformly at random and take no gradient step during collection (SB3's
        ``learning_starts``, raised to ``(learn_from_round - 1) * steps_per_round``), so a
        co-trained agent's first values come from pseudo-rewards, not from the labels alone. The
        policy update (``update_steps``) still runs at the end of every round. In [1, ``rounds``].
    :param segment_length: k; 1: the labels are single rewards (``label_fraction`` of the (s, a)
        keys or steps). Above 1, co-training only: the labels are the summed rewards of k-step
        segments of the agents' episodes, a share ``label_fraction`` of the segments, so the same
        rater effort in labelled steps (:mod:`dospcot.core.segments`).
    :param label_strategy: how labels are chosen (:mod:`dospcot.core.queries`): ``"uniform"``, a fixed
        random mask of share ``label_fraction`` (the paper's setting); or a rater with a budget who,
        after each round's collection, labels the samples chosen ``"random"``-ly, by ``"outcomes"``
        (the kinds of episode end first), by ``"uncertainty"`` (the views' classifiers' smallest
        margins) or by ``"disagreement"`` (co-testing: where the views' classifiers disagree; two or
        more views, or a reward model's ensemble); ``"outcomes+disagreement"`` and
        ``"outcomes+uncertainty"`` split the chosen queries equally between their two parts.
        Co-training and the reward-model peer only.
    :param label_budget: the answers a run may buy over its whole length, whatever its number of
        agents or views (an active ``label_strategy``); 0: at most ``ceil(label_fraction x samples
        met)`` in all, as the uniform mask would reveal among them.
    :param query_schedule: how ``label_budget`` spreads over the rounds: ``"asap"`` (all of it as soon
        as there are candidates), ``"even"`` (an equal share a round) or ``"decay"`` (round r's share
        in proportion to 1 / r). What a round could not spend carries forward.
    :param first_round_share: the most of ``label_budget`` round 1 may spend, in (0, 1] (1: no cap);
        what it holds back goes to the next rounds' schedule.
    :param query_pool_factor: the guided queries of a round choose among at most this many times their
        number of candidates, drawn at random (the recent samples first, ``query_recent_rounds``);
        0: among every candidate.
    :param query_class_floor: the share of a round's chosen queries split equally over the reward
        classes the views' classifiers predict, each class's best candidates first, so a rare class
        is asked about (0: none; needs fitted classifiers, so from round 2).
    :param query_skip_confidence: a candidate every view predicts the same class for, each with at
        least this probability, is not queried (1: none is skipped; from round 2).
    :param query_random_share: the share of each round's queries an active strategy draws at random.
    :param query_end_states: how ``"outcomes"`` picks among the steps that ended an episode:
        ``"random"``, or ``"spread"``: over the distinct states the ends reached, those no label has
        shown first, before any is asked twice (:func:`dospcot.core.end_states.spread_ends`), so a rare
        outcome such as a sparse task's goal is asked about early.
    :param query_recent_rounds: prefer the samples first met in the latest this many rounds (0: all).
    :param stop_patience: stop a run once this many rounds in a row brought its agents' greedy
        evaluation no new best (mean success, then mean normalised score), counted from the first
        round whose mean greedy return beat a random policy's, so ``rounds`` is a cap rather than a
        length a new task must be guessed at; 0: every round runs. The run's ``summary.json`` says why
        it stopped (``stopped_because``).
    :param rater: who answers the queries: ``"simulated"`` (the hidden reward) or ``"file"`` (a person:
        each round's queries go to the run folder's ``queries/round_<r>.csv`` and the run stops until
        ``dospcot train --resume`` finds them answered).
    :param agent_draws: whose random draws (exploration, replay batches) the agents make:
        ``"shared"``, the global generators in turn, so an agent's draws depend on the agents built
        and trained before it; or ``"own"``, each agent its own, so agent k of a co-trained run with
        every reward labelled computes what agent k of a one-view run computes, bit for bit
        (:mod:`dospcot.core.agent_draws`). A one-agent run is the same under both. A batch of seeds
        (``--batch-seeds``) always gives each member and agent its own stream.
    """

    rounds: int = 5
    steps_per_round: int = 5_000
    label_fraction: float = 0.05
    eps_start: float = 1.0
    eps_end: float = 0.05
    exploration: str = "pace"
    update_steps: int = 0
    learn_from_round: int = 1
    segment_length: int = 1
    label_strategy: LabelStrategy = "uniform"
    label_budget: int = 0
    query_schedule: QuerySchedule = "asap"
    first_round_share: float = 1.0
    query_pool_factor: int = 0
    query_class_floor: float = 0.0
    query_skip_confidence: float = 1.0
    query_random_share: float = 0.2
    query_end_states: EndStateQueries = "random"
    query_recent_rounds: int = 0
    rater: Literal["simulated", "file"] = "simulated"
    agent_draws: AgentDraws = "shared"
    stop_patience: int = 0
    cotrain_passes: int = 1
    passes_from_round: int = 1
    pass_kind: PassKind = "cotrain"
    first_labels: FirstLabels = "round_end"

    added_keys: ClassVar[dict[str, Any]] = {
        "agent_draws": "shared",
        "cotrain_passes": 1,
        "first_labels": "round_end",
        "passes_from_round": 1,
        "pass_kind": "cotrain",
        "query_end_states": "random",
        "stop_patience": 0,
    }

    def __post_init__(self) -> None:
        check_at_least(self, 1, "segment_length")
        check_at_least(self, 0, "stop_patience")
        if self.rounds < 1 or self.steps_per_round < 1:
            raise ValueError(
                f"rounds and steps_per_round must be >= 1, got {self.rounds}, {self.steps_per_round}"
            )
        if not 1 <= self.cotrain_passes <= self.steps_per_round:
            raise ValueError(
                f"cotrain_passes must lie in [1, steps_per_round = {self.steps_per_round}], "
                f"got {self.cotrain_passes}"
            )
        check_at_least(self, 1, "passes_from_round")
        check_at_least(self, 0, "update_steps")
        if self.exploration not in ("pace", "rounds"):
            raise ValueError(f"exploration must be 'pace' or 'rounds', got {self.exploration!r}")
        if not 1 <= self.learn_from_round <= self.rounds:
            raise ValueError(
                f"learn_from_round must lie in [1, rounds = {self.rounds}], got {self.learn_from_round}"
            )
        check_label_fraction(self.label_fraction)
        check_within(self, 0, 1, "eps_start", "eps_end", "query_random_share", "query_class_floor")
        check_at_least(self, 0, "query_recent_rounds", "label_budget", "query_pool_factor")
        if self.rater == "file" and not self.queries:
            raise ValueError('rater = "file" answers queries: set label_strategy to an active strategy')
        self._check_first_labels()
        self._check_budget()

    def _check_first_labels(self) -> None:
        if self.first_labels == "round_end":
            return
        if self.cotrain_passes < 2 or self.passes_from_round != 1:
            raise ValueError(
                'first_labels = "first_pass" co-trains at round 1\'s first pass: set cotrain_passes >= 2 '
                f"and passes_from_round = 1 (got {self.cotrain_passes} and {self.passes_from_round})"
            )
        if self.segment_length > 1:
            raise ValueError('first_labels = "first_pass" co-trains single rewards: set segment_length = 1')
        if self.rater == "file":
            raise ValueError(
                'first_labels = "first_pass" buys labels in the middle of round 1\'s collection, which a '
                'person\'s answers cannot pause: use rater = "simulated" or first_labels = "round_end"'
            )

    def _check_budget(self) -> None:
        if self.query_schedule not in QUERY_SCHEDULES:
            raise ValueError(f"query_schedule must be one of {QUERY_SCHEDULES}, got {self.query_schedule!r}")
        for name in ("first_round_share", "query_skip_confidence"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"{name} must lie in (0, 1], got {getattr(self, name)}")
        if self.label_budget and not self.queries:
            raise ValueError(
                "label_budget counts a rater's answers: set label_strategy to an active strategy "
                "(the uniform mask reveals the share label_fraction)"
            )
        if not self.label_budget and (self.query_schedule != "asap" or self.first_round_share < 1):
            raise ValueError(
                "query_schedule and first_round_share spread a budget counted in labels: set label_budget"
            )

    @property
    def queries(self) -> bool:
        """Whether a rater answers queries for the labels (an active ``label_strategy``), rather than
        the fixed random mask of share ``label_fraction`` revealing them."""
        return self.label_strategy != "uniform"

    @property
    def total_steps(self) -> int:
        """Env steps each agent takes in the whole run."""
        return self.rounds * self.steps_per_round

    @property
    def collect_only_steps(self) -> int:
        """Env steps per agent before ``learn_from_round``: the agents learn nothing while they take
        them (every agent's ``learning_starts`` is at least this)."""
        return (self.learn_from_round - 1) * self.steps_per_round


@dataclass(frozen=True)
class ClassifierConfig:
    """Hyperparameters of a reward classifier.

    :param model: ``"mlp"`` or ``"linear"``.
    :param loss: ``"cross_entropy"`` or ``"hinge"``.
    :param hidden: width of the MLP's hidden layer.
    :param epochs: full-batch Adam steps per fit.
    :param lr: Adam learning rate.
    :param l2: weight of the penalty 1/2 ||theta||^2, divided by the number of training samples.
    """

    model: ModelKind = "mlp"
    loss: LossKind = "cross_entropy"
    hidden: int = 32
    epochs: int = 150
    lr: float = 0.02
    l2: float = 1e-3

    def __post_init__(self) -> None:
        if self.model not in MODEL_KINDS:
            raise ValueError(f"classifier model must be one of {MODEL_KINDS}, got {self.model!r}")
        if self.loss not in LOSS_KINDS:
            raise ValueError(f"classifier loss must be one of {LOSS_KINDS}, got {self.loss!r}")
        check_at_least(self, 1, "hidden", "epochs")
        check_positive(self, "lr")
        check_at_least(self, 0, "l2")


@dataclass(frozen=True)
class CoTrainingConfig(AddedKeys):
    """Hyperparameters of the self-paced schedule.

    :param consensus_weight: the co-regularisation weight, SPaMCo's gamma (default 0.3): before
        ranking, a sample's score for its consensus class is raised by this times the mean weight the
        other views give it (0: the views select alone). Not the agents' discount, ``dqn.gamma``.
    :param weighting: ``"hard"`` (SPaMCo default) or ``"soft"`` self-paced weights.
    :param add_fraction_start: add_num in round 1, as a share of the unlabelled pool.
    :param add_fraction_step: growth of that share per round (lambda falls as it grows). It is not
        capped at 1: under ``quota = "label-share"`` the per-class quotas ``ceil(share_c * add_num)``
        keep a class from taking more than its share, so only an add_num beyond |U| lets every
        class's candidates in, and U be fully admitted.
    :param quota: how add_num splits over the classes: ``"label-share"`` (SPaMCo: in proportion to
        the labels) or ``"candidates"`` (each class the same share of the samples predicted as it;
        :mod:`dospcot.core.selection`).
    :param tol: stop once under this share of pseudo-labels changed in a round (0 disables).
    :param stop_when_fully_admitted: stop once every unlabelled sample is admitted.
    :param max_classes: the most distinct reward values a run may see.
    :param classifier: the reward classifiers' hyperparameters.
    :param numerics: how the reward classifiers fit (:data:`dospcot.core.self_paced.NUMERICS`): 1, in
        float64 over the whole pool (version 1 of the defaults); 2, in float32 over the samples that
        carry weight, several times cheaper on large pools (docs/guide/profile.md), and the default
        from version 3 of the defaults on: the numerics study showed it non-inferior to 1 on
        both its presets (docs/results/numerics.md); 3, 2's fits and agents
        whose Q-networks read a view of 0s and 1s through a sparse first layer, with a fused Adam (the
        same arithmetic as 2 in another order: equal up to float32 rounding), opt-in: the numerics-3
        study did not show it non-inferior (docs/results/numerics-3.md). Every run names it in
        ``run_info.json``; a run folder or checkpoint written before the key existed reads as 1
        (``added_keys``), and a study compares the two only where its grid varies it.
    :param ensemble_size: the reward-model peer's (``method = "reward-model"``) classifiers per view,
        each from its own initial parameters and its own bootstrap of the labels.
    :param refit_new_classes: when a run's labels show a reward class for the first time after round
        1, each view's classifier first learns the labels alone again, as in round 1, before the round
        selects: a class's output had never been trained, so its scores were those of its random
        initial parameters, and the consensus could give it to most of the pool.
    :param pseudo_rewards: what an admitted sample's reward in the agents' reward table is:
        ``"classifiers"``, the decoded consensus class of the views' classifiers (the method), or
        ``"hidden"``, its true (hidden) reward: a control that keeps everything else (which samples are
        admitted and when, their weights, the pace, the classifiers' fits and scores) as the
        classifiers decide it, so that a gap to the oracle splits into wrong pseudo-rewards and what
        the path itself loses. Under ``"hidden"`` the record's pseudo-reward accuracy describes the
        rewards given (1 wherever a sample is admitted); each view's figures still score its classifier.
    """

    consensus_weight: float = 0.3
    weighting: Weighting = "hard"
    add_fraction_start: float = 0.2
    add_fraction_step: float = 0.4
    quota: Quota = "label-share"
    tol: float = 0.0
    stop_when_fully_admitted: bool = False
    max_classes: int = 16
    classifier: ClassifierConfig = field(default_factory=ClassifierConfig)
    numerics: int = 1
    ensemble_size: int = 3
    refit_new_classes: bool = False
    pseudo_rewards: PseudoRewards = "classifiers"

    renamed_keys: ClassVar[dict[str, str]] = {"gamma": "consensus_weight"}
    """Keys of older configs and their names now."""
    added_keys: ClassVar[dict[str, Any]] = {
        "numerics": 1,
        "refit_new_classes": False,
        "pseudo_rewards": "classifiers",
    }

    def __post_init__(self) -> None:
        if self.consensus_weight < 0:
            raise ValueError(f"consensus_weight must be >= 0, got {self.consensus_weight}")
        if self.weighting not in WEIGHTINGS:
            raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {self.weighting!r}")
        if self.quota not in QUOTAS:
            raise ValueError(f"quota must be one of {QUOTAS}, got {self.quota!r}")
        if self.pseudo_rewards not in PSEUDO_REWARDS:
            raise ValueError(f"pseudo_rewards must be one of {PSEUDO_REWARDS}, got {self.pseudo_rewards!r}")
        if self.add_fraction_start <= 0:
            raise ValueError(f"add_fraction_start must be > 0, got {self.add_fraction_start}")
        if self.add_fraction_step < 0:
            raise ValueError(f"add_fraction_step must be >= 0, got {self.add_fraction_step}")
        check_within(self, 0, 1, "tol")
        check_at_least(self, 1, "max_classes", "ensemble_size")
        if self.numerics not in NUMERICS_VERSIONS:
            raise ValueError(
                f"numerics must be one of {', '.join(map(str, NUMERICS_VERSIONS))}, got {self.numerics}"
            )
