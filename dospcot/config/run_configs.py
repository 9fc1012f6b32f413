"""The root of a config: :class:`TrainConfig` (one run of SB3 agents on a task) and
:class:`PaperConfig` (one seed of the seed paper's tabular protocol).

Every field is checked without I/O when the dataclass is built, and nothing here knows a task: what a
task adds to the checks (its views, what its sections allow together) is the task spec's
(:meth:`dospcot.tasks.registry.Task.check_config`), which :func:`dospcot.tasks.load_config` applies.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from dospcot.config.agent_sections import DQNConfig, TabularAgentConfig
from dospcot.config.choices import DEFAULT_VIEWS, OLD_METHOD_NAMES, Method
from dospcot.config.errors import ConfigError
from dospcot.config.learning_sections import CoTrainingConfig, TrainingConfig
from dospcot.config.paper_sections import TabularConfig
from dospcot.config.task_sections import DemonstrationsConfig, EnvConfig, GymConfig, HighwayConfig
from dospcot.config.versions import ADOPTED, FIRST

RUN_AGENT_KINDS: tuple[str, ...] = ("esarsa_dqn", "dqn", "tabular")
SELF_PACED_KEYS: frozenset[str] = frozenset(
    f"cotraining.{key}"
    for key in (
        "consensus_weight",
        "weighting",
        "add_fraction_start",
        "add_fraction_step",
        "quota",
        "tol",
        "stop_when_fully_admitted",
        "refit_new_classes",
    )
)
"""The ``[cotraining]`` keys of the self-paced schedule, which only co-training reads."""
REWARD_LEARNER_KEYS: frozenset[str] = SELF_PACED_KEYS | {
    "training.pass_kind",
    "cotraining.ensemble_size",
    "cotraining.classifier",
    "cotraining.pseudo_rewards",
    "training.cotrain_passes",
    "training.passes_from_round",
    "training.first_labels",
}
"""The keys read by a method that learns rewards alone (``cotraining.classifier``: its section), which
the baselines never read. ``numerics`` is not among them: every run names it in its
``run_info.json``, so a study pins it for every arm."""


@dataclass(frozen=True)
class TrainConfig:
    """One ``dospcot train`` run.

    :param name: the run's name: it writes under ``runs/<name>/<stamp>/``.
    :param seed: seeds the mask, the agents and the classifiers.
    :param defaults: the version of the defaults the config was written against
        (:mod:`dospcot.config.versions`); a key the config does not set takes that version's default.
    :param method: ``oracle``, ``masked-zero``, ``labels-only``, ``dospcot`` (DOSPCoT; one view is
        self-training) or ``reward-model`` (the peer without co-training: an ensemble of reward
        classifiers per view fitted on the labels alone rewards every unlabelled sample).
    :param views: one view per agent, from the task's views (the grid's ``coords``, ``patch``, ``rays``).
        A view named twice is a same-sensor twin: two agents and two classifiers on one sensor, each
        from its own initial weights and draws (a second model without a second view); its second
        agent's files and figures are named ``<view>-2`` (:attr:`agent_names`).
    :param agents: the agent kind of each view (``esarsa_dqn``, ``dqn`` or, on a grid, ``tabular``);
        empty: ``agent`` for every view.
    :param agent: the agent kind of every view when ``agents`` is empty (``--set agent=tabular``
        switches a preset's agents whatever its number of views).
    :param task: a registered task (:mod:`dospcot.tasks`): ``grid`` (the ``[env]`` section), ``highway``
        (``[highway]``) or ``gym`` (any gymnasium env, ``[gym]``); a config with ``task = "paper"`` is a
        :class:`PaperConfig`.
    """

    name: str = "run"
    seed: int = 0
    defaults: int = ADOPTED
    method: Method = "dospcot"
    views: tuple[str, ...] = DEFAULT_VIEWS
    agents: tuple[str, ...] = ()
    agent: str = "esarsa_dqn"
    task: str = "grid"
    env: EnvConfig = field(default_factory=EnvConfig)
    highway: HighwayConfig = field(default_factory=HighwayConfig)
    gym: GymConfig = field(default_factory=GymConfig)
    training: TrainingConfig = field(default_factory=TrainingConfig)
    dqn: DQNConfig = field(default_factory=DQNConfig)
    tabular_agent: TabularAgentConfig = field(default_factory=TabularAgentConfig)
    cotraining: CoTrainingConfig = field(default_factory=CoTrainingConfig)
    demonstrations: DemonstrationsConfig = field(default_factory=DemonstrationsConfig)

    added_keys: ClassVar[dict[str, Any]] = {"defaults": FIRST}
    """A run folder written before versions of the defaults existed was written against the first."""
    renamed_values: ClassVar[dict[str, dict[str, str]]] = {"method": OLD_METHOD_NAMES}
    """Values read under a newer spelling, by key: an older config's ``method = "cotrain"`` is today's
    ``"dospcot"``."""

    unread_keys: ClassVar[dict[str, frozenset[str]]] = {
        "dospcot": frozenset({"cotraining.ensemble_size"}),
        "reward-model": SELF_PACED_KEYS,
        "oracle": REWARD_LEARNER_KEYS,
        "masked-zero": REWARD_LEARNER_KEYS,
        "labels-only": REWARD_LEARNER_KEYS,
    }
    """The keys (or sections) each ``method`` never reads: a config that sets one is refused, since the
    setting would change nothing (:func:`dospcot.tasks.load_config`)."""

    def __post_init__(self) -> None:
        check_name_and_seed(self.name, self.seed)
        if self.agents and len(self.agents) != len(self.views):
            raise ConfigError(
                f"agents: need one agent kind per view ({len(self.views)}), got {len(self.agents)}"
            )
        allowed_kinds = ", ".join(RUN_AGENT_KINDS)
        for key, kinds in (("agents", self.agents), ("agent", (self.agent,))):
            unknown = [kind for kind in kinds if kind not in RUN_AGENT_KINDS]
            if unknown:
                raise ConfigError(f"{key}: unknown agent kind {unknown[0]!r}; allowed: {allowed_kinds}")
        self._check_demonstrations()
        self._check_segments()
        self._check_queries()

    def _check_demonstrations(self) -> None:
        demos = self.demonstrations
        if demos.margin_loss_weight and (demos.episodes or demos.file) and "tabular" in self.agent_kinds:
            raise ConfigError(
                "demonstrations.margin_loss_weight: tabular agents have no large-margin loss; set it to 0 "
                "to use the demonstrations as labels only"
            )

    def _check_segments(self) -> None:
        if self.training.segment_length == 1:
            return
        if self.method != "dospcot":  # the reward-model peer too: its ensembles learn single rewards
            raise ConfigError(
                f'training.segment_length: segment labels need co-training (method = "dospcot"; one '
                f'view is self-training), got method = "{self.method}"'
            )
        if self.demonstrations.labels and (self.demonstrations.episodes or self.demonstrations.file):
            raise ConfigError(
                "training.segment_length: segment labels reveal no single reward, so demonstrations "
                "cannot be labels too; set demonstrations.labels = false"
            )
        if self.training.cotrain_passes > 1:
            # A pass inside a round would cut the segments of the episodes still running.
            raise ConfigError(
                "training.cotrain_passes: segment labels are co-trained once a round, on whole segments; "
                f"set cotrain_passes = 1 with segment_length = {self.training.segment_length}"
            )

    def _check_queries(self) -> None:
        strategy = self.training.label_strategy
        if not self.training.queries:
            return
        if not self.learns_rewards:
            raise ConfigError(
                f'training.label_strategy: "{strategy}" queries the rewards co-training needs (method = '
                f'"dospcot"; one view is self-training; or "reward-model"), got method = "{self.method}"; '
                'use "uniform"'
            )
        if "disagreement" in strategy.split("+") and len(self.views) < 2 and self.method == "dospcot":
            raise ConfigError(
                'training.label_strategy: "disagreement" asks where two views\' classifiers disagree, and '
                f'the run has one view ({self.views[0]}); use "uncertainty" for one view'
            )
        if (
            "disagreement" in strategy.split("+")
            and self.method == "reward-model"
            and len(self.views) * self.cotraining.ensemble_size < 2
        ):
            raise ConfigError(
                'training.label_strategy: "disagreement" asks where the reward model\'s members disagree, '
                "and the run has one view with cotraining.ensemble_size = 1; raise ensemble_size to 2 or "
                'more, or use "uncertainty"'
            )
        if self.training.segment_length > 1:
            raise ConfigError(
                "training.label_strategy: queries reveal single rewards, segment labels none; "
                f'set label_strategy = "uniform" with segment_length = {self.training.segment_length}'
            )

    def check_read(self, given: set[str]) -> None:
        """Refuse the keys of ``given`` (dotted names a person wrote) that this config's ``method``
        never reads, and a label share (``training.label_fraction``) where a rater buys a budget of
        answers, which leaves the share unread.

        :raises ConfigError: one line naming them and the method.
        """
        unread = self.unread_keys.get(self.method, frozenset())
        named = sorted(k for k in given if k in unread or any(k.startswith(f"{u}.") for u in unread))
        if named:
            raise ConfigError(
                f'{", ".join(named)}: method = "{self.method}" never reads '
                f"{'it' if len(named) == 1 else 'them'}; remove {'it' if len(named) == 1 else 'them'} "
                "or choose a method that does"
            )
        t = self.training
        if "training.label_fraction" in given and t.queries and t.label_budget:
            # Under a version that buys a budget, a share set alone would be silently ignored.
            raise ConfigError(
                f"training.label_fraction: unread, since a rater buys training.label_budget = "
                f'{t.label_budget} answers (label_strategy = "{t.label_strategy}", version {self.defaults} '
                "of the defaults); for a uniform mask of that share also set training.label_strategy = "
                '"uniform", for a budget of that share of the samples met set training.label_budget = 0'
            )

    @property
    def learns_rewards(self) -> bool:
        """Whether the run fits reward classifiers that reward the unlabelled samples: co-training
        (``dospcot``) or the reward-model peer (``reward-model``)."""
        return self.method in ("dospcot", "reward-model")

    @property
    def agent_kinds(self) -> tuple[str, ...]:
        """The agent kind of each view."""
        return self.agents or (self.agent,) * len(self.views)

    @property
    def agent_names(self) -> tuple[str, ...]:
        """Each agent's name in its files and figures: its view, numbered from the view's second agent
        on (``("image", "image-2")`` for a twin on ``image``)."""
        names = []
        for k, view in enumerate(self.views):
            count = self.views[: k + 1].count(view)
            names.append(view if count == 1 else f"{view}-{count}")
        return tuple(names)

    @property
    def buffer_size(self) -> int:
        """Every neural agent's replay capacity: steps beyond a run's total never enter the buffer, so
        capping it changes nothing but memory and the size of every checkpoint."""
        return min(self.dqn.buffer_size, self.training.total_steps)

    @property
    def mask_fraction(self) -> float:
        """The random share of the run's reward mask: every reward for the oracle, none where a rater
        buys the labels (``training.queries``), else ``training.label_fraction``."""
        if self.method == "oracle":
            return 1.0
        return 0.0 if self.training.queries else self.training.label_fraction

    def to_dict(self) -> dict[str, Any]:
        """The config as plain TOML-ready values (tuples become lists), every section included; a run
        folder's ``config.toml`` leaves out the sections its task does not read
        (:meth:`dospcot.tasks.registry.Task.config_table`)."""
        return plain(dataclasses.asdict(self))


@dataclass(frozen=True)
class PaperConfig:
    """One seed of the seed paper's protocol on masked CliffWalking (``task = "paper"``).

    The protocol fixes its runs (:func:`dospcot.run.paper_protocol.protocol_specs`: 26 tabular runs, 37
    agents, per seed: every agent kind alone under each baseline, homogeneous pairs at three gammas,
    Expected SARSA with the other kinds); a config sets the seed and the hyperparameters every run shares.

    :param name: the run's name: it writes under ``runs/<name>/<stamp>/``.
    :param seed: draws the labelled keys, the exploration streams and the classifiers.
    :param defaults: the version of the defaults the config was written against
        (:mod:`dospcot.config.versions`); no version moves a paper-protocol key.
    :param tabular: the hyperparameters every run of the protocol shares.
    """

    name: str = "paper"
    seed: int = 0
    defaults: int = ADOPTED
    task: Literal["paper"] = "paper"
    tabular: TabularConfig = field(default_factory=TabularConfig)

    added_keys: ClassVar[dict[str, Any]] = {"defaults": FIRST}
    """A run folder written before versions of the defaults existed was written against the first."""

    def __post_init__(self) -> None:
        check_name_and_seed(self.name, self.seed)

    def to_dict(self) -> dict[str, Any]:
        """The config as plain TOML-ready values."""
        return plain(dataclasses.asdict(self))


NAME_MAX_BYTES = 255
"""The longest file name, in bytes, that Linux's and macOS's file systems take."""


def folder_name_problem(name: str) -> str | None:
    """Why ``name`` cannot be the name of one folder inside another (a run's or a sweep's), or None:
    every name a person gives a folder passes this one rule, so none escapes its parent (``..``,
    ``/``), nests (``a/b``), hides (``.x``) or is refused by the file system."""
    if not name.strip():
        return "an empty name"
    if "/" in name or "\\" in name:
        return "a path, not one folder's name (no / or \\)"
    if name.startswith("."):
        return "a name starting with '.' (hidden, or . and .. themselves)"
    if "\0" in name or any(ord(char) < 32 for char in name):
        return "a name holding a control character"
    if len(name.encode("utf-8", "surrogatepass")) > NAME_MAX_BYTES:
        return f"a name longer than a file system takes ({NAME_MAX_BYTES} bytes)"
    return None


def check_name_and_seed(name: str, seed: int) -> None:
    """The checks every config's ``name`` and ``seed`` pass."""
    problem = folder_name_problem(name)
    if problem is not None:
        raise ConfigError(f"name: must be a plain folder name, got {name!r}: {problem}")
    if seed < 0:
        raise ConfigError(f"seed: must be >= 0, got {seed}")


def plain(value: Any) -> Any:
    """``value`` with tuples as lists, as TOML holds them."""
    if isinstance(value, dict):
        return {key: plain(item) for key, item in value.items()}
    if isinstance(value, tuple | list):
        return [plain(item) for item in value]
    return value


RunConfig = TrainConfig | PaperConfig
"""Any config a run folder holds."""
