"""The configuration of ``dospcot train``: TOML presets, ``--set`` overrides and validation.

A config is a TOML table read with the stdlib's :mod:`tomllib`. Its keys mirror
:class:`TrainConfig`; sections (``[env]``, ``[training]``, ``[dqn]``, ``[tabular_agent]``,
``[cotraining]``, ``[cotraining.classifier]``, ``[demonstrations]``) mirror its nested dataclasses.
A config with ``task = "paper"`` is a :class:`PaperConfig` instead (one seed of the seed paper's
tabular protocol, its ``[tabular]`` section a :class:`~dospcot.tabular_cotraining.TabularConfig`).
Every key is checked against the dataclass fields and their type hints before anything is built, so a
typo or a wrong type stops the run with one line (:class:`ConfigError`) naming the key and what is
allowed.

Presets ship in ``dospcot/presets/*.toml``; a name without ``.toml`` is looked up there, anything
else is read as a path. A config may start from another with ``extends = "<preset or path>"``: its
tables are merged key by key over the base's.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import tomllib
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from stable_baselines3 import DQN

from dospcot.cotraining import CoTrainingConfig
from dospcot.cotraining_round import TrainingConfig
from dospcot.demonstrations import Demonstrations, DemonstrationsConfig, load_agent
from dospcot.envs.fast_highway import FastHighwayEnv
from dospcot.envs.gym_sensors import check_gym_task
from dospcot.envs.highway import FAST_HIGHWAY_ID, HIGHWAY_ENV_IDS, highway_view_names, try_highway_config
from dospcot.policies import ExpectedSarsaDQN
from dospcot.tabular_cotraining import TabularConfig

GRID_VIEWS: tuple[str, ...] = ("coords", "patch", "rays")
TASK_SECTIONS: dict[str, str] = {"grid": "env", "highway": "highway", "gym": "gym"}
"""Each task of :class:`TrainConfig` and the section that sets it up."""
RUN_AGENT_KINDS: tuple[str, ...] = ("esarsa_dqn", "dqn", "tabular")


class ConfigError(ValueError):
    """A config that cannot run; the message is one line naming the key and what is allowed."""


@dataclass(frozen=True)
class EnvConfig:
    """The masked grid world (:class:`dospcot.envs.GridWorld`).

    :param size: side N of the map.
    :param layout_seed: seed of the map (the run's ``seed`` draws the mask and the agents).
    :param lava_density: share of lava cells.
    :param wall_density: share of wall cells.
    :param step_cost: reward of an ordinary step.
    :param lava_penalty: reward of a step into lava (which returns to the start).
    :param goal_reward: reward of the step into the goal (which ends the episode).
    :param exploring_starts: start training episodes on a uniformly drawn free cell (evaluation always
        starts from the map's start).
    :param max_episode_steps: the episode length limit of the evaluation from the map's start (0: 4 N).
    :param train_episode_steps: the episode length limit while training (0: ``max_episode_steps``);
        with exploring starts, short episodes scattered over the map reach the goal far more often
        than long ones.
    :param patch_size: side k of the ``patch`` view (odd).
    :param compass: every view also reads the goal's offset (a goal compass): ``"none"``, ``"axes"``
        (one-hot per axis) or ``"cell"`` (one-hot over the map's cells; :mod:`dospcot.envs.gridworld`).
    :param ray_encoding: how the ``rays`` view reads a distance d: ``"distance"`` (d / N) or
        ``"inverse"`` (1 / d, so a hazard next to the agent reads 1 on any map size).
    :param blind_spot_rate: the share of lava cells each terrain view (``patch``, ``rays``) reads as
        free, a persistent blind spot drawn per run seed and view (0: error-free sensors).
    :param blind_spots: ``"independent"`` (each view misses its own cells) or ``"identical"`` (every
        view misses the same cells, the control).
    :param monitored_columns: a reward monitor: every reward of a state in the map's first this many
        columns is revealed, and ``training.label_fraction`` is the share of the other keys (0: none).
    """

    size: int = 16
    layout_seed: int = 0
    lava_density: float = 0.1
    wall_density: float = 0.1
    step_cost: float = -1.0
    lava_penalty: float = -100.0
    goal_reward: float = 0.0
    exploring_starts: bool = False
    max_episode_steps: int = 0
    train_episode_steps: int = 0
    patch_size: int = 5
    compass: Literal["none", "axes", "cell"] = "none"
    ray_encoding: Literal["distance", "inverse"] = "distance"
    blind_spot_rate: float = 0.0
    blind_spots: Literal["independent", "identical"] = "independent"
    monitored_columns: int = 0

    def __post_init__(self) -> None:
        if not 4 <= self.size <= 256:
            raise ValueError(f"size must lie in [4, 256], got {self.size}")
        if not 0.0 <= self.blind_spot_rate <= 1.0:
            raise ValueError(f"blind_spot_rate must lie in [0, 1], got {self.blind_spot_rate}")
        if not 0 <= self.monitored_columns <= self.size:
            raise ValueError(
                f"monitored_columns must lie in [0, size = {self.size}], got {self.monitored_columns}"
            )
        if self.max_episode_steps < 0 or self.train_episode_steps < 0:
            raise ValueError(
                "max_episode_steps and train_episode_steps must be >= 0 (0: the default), "
                f"got {self.max_episode_steps}, {self.train_episode_steps}"
            )
        if self.patch_size < 1 or self.patch_size % 2 == 0:
            raise ValueError(f"patch_size must be odd and positive, got {self.patch_size}")
        if self.compass == "cell" and self.size > 64:
            # One input per cell: a view table of N^2 x N^2 floats (64 x 64: 64 MiB) grows too fast.
            raise ValueError(f'compass = "cell" needs size <= 64, got {self.size}; use "axes"')

    @property
    def episode_steps(self) -> int:
        """The episode length limit, ``4 N`` unless set."""
        return self.max_episode_steps or 4 * self.size


@dataclass(frozen=True)
class HighwayConfig:
    """A highway task (``task = "highway"``): highway-env's or our fast env, with sensor views.

    :param env_id: ``"highway-fast-v0"``, ``"highway-v0"``, ``"merge-v0"``, ``"roundabout-v0"``
        (highway-env, the ``highway`` extra) or ``"dospcot/FastHighway-v0"`` (ours, numpy).
    :param episode_steps: policy steps of an evaluation episode (highway-fast-v0: its 30 s at 1 Hz); an
        episode that lasts them all counts as a success, and they bound the normalised score.
    :param reward_classes: K, the quantile bins of the continuous reward.
    :param eval_episodes: greedy evaluation episodes per agent and round.
    :param config: the task's own config overrides: highway-env's keys (``vehicles_count``,
        ``duration``, ...), or :class:`dospcot.envs.FastHighwayConfig`'s for the fast env.
    :param reveal_first_steps: a reward monitor: the first this many steps of every training episode
        are revealed, later ones with probability ``training.label_fraction`` (0: none).
    """

    env_id: str = "highway-fast-v0"
    episode_steps: int = 30
    reward_classes: int = 5
    eval_episodes: int = 10
    config: dict[str, Any] = field(default_factory=dict)
    reveal_first_steps: int = 0

    def __post_init__(self) -> None:
        if self.episode_steps < 1 or self.reward_classes < 1 or self.eval_episodes < 1:
            raise ValueError(
                "episode_steps, reward_classes and eval_episodes must be >= 1, got "
                f"{self.episode_steps}, {self.reward_classes}, {self.eval_episodes}"
            )
        if self.reveal_first_steps < 0:
            raise ValueError(f"reveal_first_steps must be >= 0, got {self.reveal_first_steps}")


@dataclass(frozen=True)
class GymConfig:
    """Any gymnasium task with discrete actions (``task = "gym"``; docs/your_env.md), with views
    computed from its observation (:mod:`dospcot.envs.gym_sensors`). Every step is one pool sample
    and is revealed with probability ``training.label_fraction``.

    :param env_id: a registered gymnasium id (``"CartPole-v1"``; ``"package:Env-v0"`` imports the
        package that registers it first), or a dotted path ``"package.module:function"`` to a function
        that returns the env.
    :param env_kwargs: keyword arguments of the env.
    :param wrappers: wrappers applied in order before the views read the observation: gymnasium's by
        class name (``"FlattenObservation"``) or any class by dotted path.
    :param train_wrappers: wrappers of the training episodes only, applied first (inside
        ``wrappers``); evaluation episodes run without them. E.g. exploring starts on MiniGrid
        (``"dospcot.envs.minigrid_views:RandomStart"``).
    :param views: each view's name and what it reads: ``"observation"`` (the whole observation), a key
        of a ``Dict`` observation, or a dotted path ``"package.module:function"`` to a function of the
        observation. The run's ``views`` pick among these names.
    :param episode_steps: the step limit of an evaluation episode.
    :param reward_classes: K, the quantile bins of the reward.
    :param eval_episodes: greedy evaluation episodes per agent and round.
    :param success_return: an evaluation episode whose true return exceeds this counts as a success.
    :param max_return: the best return an evaluation episode can reach, ``R_max`` of the normalised
        score; ``inf`` (the default): not known, and the normalised score is NaN.
    :param state_key: names each state by a hashable key: ``"minigrid"`` (the agent's cell and
        direction, what it carries, the map) or a dotted path to a function of the unwrapped env.
        The pool then holds (state key, action) pairs, each labelled with probability
        ``training.label_fraction`` for all its visits, as on the grid; empty: single steps.
    :param read_termination: the reward classifiers also read whether a step ended its episode (the
        env's ``terminated``, which the mask leaves visible). Where only rare steps end an episode and
        a rare reward comes with them (MiniGrid's goal), a pseudo-reward of that class on a step that
        goes on is then easy to rule out: such a step, taken again and again, would pay the agent a
        loop worth more than the goal.
    :param episode_end_classes: a reward class the labels show only on steps that ended their
        episode (MiniGrid's goal) is given only to such steps: no view predicts it on a step that goes
        on, so no pseudo-reward pays a loop (:func:`dospcot.reward_classes.episode_end_class_mask`).
        A class also labelled on a step that goes on stays open everywhere.
    """

    env_id: str = ""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    wrappers: tuple[str, ...] = ()
    train_wrappers: tuple[str, ...] = ()
    views: dict[str, str] = field(default_factory=dict)
    episode_steps: int = 100
    reward_classes: int = 5
    eval_episodes: int = 10
    success_return: float = 0.0
    max_return: float = math.inf
    state_key: str = ""
    read_termination: bool = False
    episode_end_classes: bool = False

    def __post_init__(self) -> None:
        if self.episode_steps < 1 or self.reward_classes < 1 or self.eval_episodes < 1:
            raise ValueError(
                "episode_steps, reward_classes and eval_episodes must be >= 1, got "
                f"{self.episode_steps}, {self.reward_classes}, {self.eval_episodes}"
            )
        for name, spec in self.views.items():
            if not isinstance(spec, str):
                raise ValueError(f"views.{name}: expected a string (a key, a dotted path), got {spec!r}")
        for name, value in self.env_kwargs.items():
            if value is None:  # TOML has no null: the run's config.toml could not hold it
                raise ValueError(f"env_kwargs.{name}: None cannot be saved in a config; leave the key out")


DQN_DEFAULTS: dict[str, Any] = {
    # SB3's defaults suit Atari's millions of steps; dospcot's runs take tens of thousands of steps on
    # small tasks with short horizons: a faster learner that starts sooner, moves its target network
    # more often and discounts more.
    "learning_rate": 1e-3,
    "buffer_size": 100_000,
    "learning_starts": 500,
    "batch_size": 64,
    "gamma": 0.97,
    "target_update_interval": 500,
}
"""Where a ``[dqn]`` default differs from stable-baselines3's ``DQN``; every other default is SB3's."""

DQN_SET_ELSEWHERE: dict[str, str] = {
    "exploration_initial_eps": "training.eps_start",
    "exploration_final_eps": "training.eps_end",
    "exploration_fraction": "training.eps_start and eps_end (the co-trainer's pace moves eps)",
    "policy_kwargs": "dqn.net_arch",
    "seed": "the run's seed",
    "tensorboard_log": "the run folder",
    "verbose": "the run (its progress bar and TensorBoard)",
}
"""SB3 ``DQN`` arguments a ``[dqn]`` section may not hold, and what sets them instead."""


def _sb3_dqn_fields() -> list[tuple[str, type, Any]]:
    """SB3 ``DQN``'s keyword arguments that a TOML value can hold (a bool, an int or a float), read from
    its signature: (name, type, default), with dospcot's default where :data:`DQN_DEFAULTS` has one."""
    fields = []
    for name, param in inspect.signature(DQN.__init__).parameters.items():
        # learning_rate may be a schedule and train_freq a tuple: a config gives the plain number.
        hint = param.annotation if param.annotation in (bool, int, float) else type(param.default)
        if name.startswith("_") or name in DQN_SET_ELSEWHERE or hint not in (bool, int, float):
            continue
        fields.append((name, hint, field(default=hint(DQN_DEFAULTS.get(name, param.default)))))
    return fields


class _DQNChecks:
    def __post_init__(self) -> None:
        for name in ("buffer_size", "batch_size", "train_freq", "target_update_interval", "n_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must be >= 0, got {self.learning_starts}")
        if not 0 < self.gamma <= 1 or not 0 < self.tau <= 1:
            raise ValueError(f"gamma and tau must lie in (0, 1], got {self.gamma}, {self.tau}")
        if self.learning_rate <= 0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate}")
        if not self.net_arch or any(width < 1 for width in self.net_arch):
            raise ValueError(
                f"net_arch needs one or more hidden layer widths, each >= 1, got {list(self.net_arch)}"
            )

    def sb3_kwargs(self) -> dict[str, Any]:
        """The agents' keyword arguments: SB3 ``DQN``'s and ``cut_windows``."""
        kwargs = dataclasses.asdict(self)
        kwargs["policy_kwargs"] = {"net_arch": list(kwargs.pop("net_arch"))}
        return kwargs


DQNConfig = dataclasses.make_dataclass(
    "DQNConfig",
    [
        *_sb3_dqn_fields(),
        ("net_arch", tuple[int, ...], field(default=(128, 128))),
        (
            "cut_windows",
            bool,
            field(default=inspect.signature(ExpectedSarsaDQN.__init__).parameters["cut_windows"].default),
        ),
    ],
    bases=(_DQNChecks,),
    frozen=True,
)
DQNConfig.__module__ = __name__  # so pickle and the docs find it here
DQNConfig.__doc__ = f"""Keyword arguments of every neural agent: each of stable-baselines3 ``DQN``'s that a
TOML value can hold, under its own name and with its own default except {", ".join(DQN_DEFAULTS)}
(:data:`DQN_DEFAULTS`); the fields are read from ``DQN``'s signature, not written out again. Two
fields are dospcot's:

:param net_arch: hidden layer widths of the Q-network (SB3's ``policy_kwargs["net_arch"]``).
:param cut_windows: :class:`~dospcot.policies.ExpectedSarsaDQN`'s own: under the max target
    (``agent = "dqn"``), end n-step windows before the first exploratory action.
"""
DQNConfig.set_elsewhere = DQN_SET_ELSEWHERE


@dataclass(frozen=True)
class TabularAgentConfig:
    """Keyword arguments of every ``tabular`` agent (:class:`dospcot.policies.TabularExpectedSarsa`):
    a Q-table over the view's observations, updated by replayed Expected-SARSA steps.

    :param learning_rate: the step size alpha in (0, 1].
    :param gamma: the discount.
    :param batch_size: replayed samples per update.
    :param train_freq: env steps between updates.
    :param gradient_steps: updates each time.
    :param learning_starts: env steps before the first update.
    :param buffer_size: replay capacity, in steps.
    :param n_steps: the longest n-step window a replayed sample spans (1: one-step updates).
    """

    learning_rate: float = 0.5
    gamma: float = 0.97
    batch_size: int = 32
    train_freq: int = 1
    gradient_steps: int = 1
    learning_starts: int = 0
    buffer_size: int = 100_000
    n_steps: int = 1

    def __post_init__(self) -> None:
        if not 0 < self.learning_rate <= 1 or not 0 < self.gamma <= 1:
            raise ValueError(
                f"learning_rate and gamma must lie in (0, 1], got {self.learning_rate}, {self.gamma}"
            )
        for name in ("batch_size", "train_freq", "gradient_steps", "buffer_size", "n_steps"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.learning_starts < 0:
            raise ValueError(f"learning_starts must be >= 0, got {self.learning_starts}")


@dataclass(frozen=True)
class TrainConfig:
    """One ``dospcot train`` run.

    :param name: the run's name: it writes under ``runs/<name>/<stamp>/``.
    :param seed: seeds the mask, the agents and the classifiers.
    :param method: ``oracle``, ``masked-zero``, ``labels-only`` or ``cotrain`` (DOSPCoT; one view is
        self-training).
    :param views: one view per agent, from ``coords``, ``patch``, ``rays``.
    :param agents: the agent kind of each view (``esarsa_dqn``, ``dqn`` or, on a grid, ``tabular``);
        empty: ``agent`` for every view.
    :param agent: the agent kind of every view when ``agents`` is empty (``--set agent=tabular``
        switches a preset's agents whatever its number of views).
    :param task: ``grid`` (the ``[env]`` section), ``highway`` (the ``[highway]`` section) or ``gym``
        (any gymnasium env, the ``[gym]`` section); a config with ``task = "paper"`` is a
        :class:`PaperConfig`.
    """

    name: str = "run"
    seed: int = 0
    method: Literal["oracle", "masked-zero", "labels-only", "cotrain"] = "cotrain"
    views: tuple[str, ...] = ("coords", "patch")
    agents: tuple[str, ...] = ()
    agent: str = "esarsa_dqn"
    task: Literal["grid", "highway", "gym"] = "grid"
    env: EnvConfig = field(default_factory=EnvConfig)
    highway: HighwayConfig = field(default_factory=HighwayConfig)
    gym: GymConfig = field(default_factory=GymConfig)
    training: TrainingConfig = field(default_factory=TrainingConfig)
    dqn: DQNConfig = field(default_factory=DQNConfig)
    tabular_agent: TabularAgentConfig = field(default_factory=TabularAgentConfig)
    cotraining: CoTrainingConfig = field(default_factory=CoTrainingConfig)
    demonstrations: DemonstrationsConfig = field(default_factory=DemonstrationsConfig)

    def __post_init__(self) -> None:
        _check_name_and_seed(self.name, self.seed)
        if self.task == "gym" and not self.gym.env_id:
            raise ConfigError('gym.env_id: a task = "gym" run needs one (a gymnasium id or a dotted path)')
        if self.task == "gym" and not self.gym.views:
            raise ConfigError(
                'gym.views: a task = "gym" run needs its views, e.g. views = {state = "observation"}'
            )
        allowed = ", ".join(self.view_names)
        if not self.views:
            raise ConfigError(f"views: need at least one view; allowed: {allowed}")
        for view in self.views:
            if view not in self.view_names:
                raise ConfigError(f"views: the {self.task_name} has no view {view!r}; allowed: {allowed}")
        if len(set(self.views)) != len(self.views):
            raise ConfigError(f"views: each view may appear once, got {list(self.views)}")
        if self.agents and len(self.agents) != len(self.views):
            raise ConfigError(
                f"agents: need one agent kind per view ({len(self.views)}), got {len(self.agents)}"
            )
        allowed_kinds = ", ".join(RUN_AGENT_KINDS)
        for key, kinds in (("agents", self.agents), ("agent", (self.agent,))):
            unknown = [kind for kind in kinds if kind not in RUN_AGENT_KINDS]
            if unknown:
                raise ConfigError(f"{key}: unknown agent kind {unknown[0]!r}; allowed: {allowed_kinds}")

        # Another task's section would be accepted and change nothing; at its defaults (as in the
        # config.toml of a run folder written before it was left out) it says nothing either.
        read = TASK_SECTIONS[self.task]
        for unread in self._unread_sections:
            if getattr(self, unread) != type(getattr(self, unread))():
                raise ConfigError(
                    f'{unread}: a task = "{self.task}" run does not read the [{unread}] section; its task '
                    f"is set in [{read}]"
                )
        if self.task != "grid" and "tabular" in self.agent_kinds:
            key = "agents" if self.agents else "agent"
            neural = ", ".join(kind for kind in RUN_AGENT_KINDS if kind != "tabular")
            raise ConfigError(
                f"{key}: 'tabular' needs a discrete task (task = \"grid\"); allowed on "
                f"{self.task_name}: {neural}"
            )
        self._check_demonstrations()
        self._check_segments()
        if self.task == "highway":
            _check_highway_task(self.highway)
        if self.task == "gym":
            try:
                check_gym_task(
                    self.gym.env_id,
                    self.gym.env_kwargs,
                    self.gym.wrappers,
                    self.gym.views,
                    self.gym.state_key,
                    self.gym.train_wrappers,
                )
            except ValueError as err:
                raise ConfigError(str(err)) from None

    def _check_demonstrations(self) -> None:
        demos = self.demonstrations
        if (demos.file or demos.agent) and self.task == "grid":
            source = "file" if demos.file else "agent"
            raise ConfigError(
                f"demonstrations.{source}: a grid run's demonstrations come from value iteration "
                '(demonstrations.episodes); a file or a saved agent serves task = "highway" or "gym"'
            )
        if demos.episodes and self.task != "grid" and not (demos.file or demos.agent):
            raise ConfigError(
                f'demonstrations.episodes: a task = "{self.task}" run\'s demonstrations come from a file '
                "or a saved agent: set demonstrations.file or demonstrations.agent (docs/demonstrations.md)"
            )
        if demos.file:
            try:
                Demonstrations.load(demos.file)
            except ValueError as err:
                raise ConfigError(f"demonstrations.file: {err}") from None
        if demos.agent:
            if demos.agent_view and demos.agent_view not in self.view_names:
                raise ConfigError(
                    f"demonstrations.agent_view: the {self.task_name} has no view {demos.agent_view!r}; "
                    f"allowed: {', '.join(self.view_names)}"
                )
            try:
                load_agent(demos.agent, demos.agent_algorithm)
            except ValueError as err:
                raise ConfigError(f"demonstrations.{err}") from None
        reads_ends = [k for k in ("read_termination", "episode_end_classes") if getattr(self.gym, k)]
        if (demos.file or demos.agent) and demos.labels and self.task == "gym" and reads_ends:
            raise ConfigError(
                f"gym.{reads_ends[0]}: demonstrations do not record which of their steps ended an episode, "
                "so as labels they cannot join a pool that reads it; set demonstrations.labels = false"
            )
        if (demos.episodes or demos.file) and demos.margin_loss_weight and "tabular" in self.agent_kinds:
            raise ConfigError(
                "demonstrations.margin_loss_weight: tabular agents have no large-margin loss; set it to 0 "
                "to use the demonstrations as labels only"
            )

    def _check_segments(self) -> None:
        k = self.training.segment_length
        if k == 1:
            return
        if self.method != "cotrain":
            raise ConfigError(
                f'training.segment_length: segment labels need co-training (method = "cotrain"; one '
                f'view is self-training), got method = "{self.method}"'
            )
        if self.demonstrations.labels and (self.demonstrations.episodes or self.demonstrations.file):
            raise ConfigError(
                "training.segment_length: segment labels reveal no single reward, so demonstrations "
                "cannot be labels too; set demonstrations.labels = false"
            )
        monitor = {"grid": self.env.monitored_columns, "highway": self.highway.reveal_first_steps}
        if monitor.get(self.task):
            raise ConfigError(
                "training.segment_length: segment labels reveal no single reward, so they cannot be "
                "combined with a reward monitor"
            )

    @property
    def _unread_sections(self) -> list[str]:
        return [section for task, section in TASK_SECTIONS.items() if task != self.task]

    @property
    def task_name(self) -> str:
        """The task, in words."""
        return {"grid": "grid world", "highway": self.highway.env_id, "gym": self.gym.env_id}[self.task]

    @property
    def view_names(self) -> tuple[str, ...]:
        """The views the task offers."""
        if self.task == "grid":
            return GRID_VIEWS
        if self.task == "gym":
            return tuple(self.gym.views)
        return highway_view_names(self.highway.env_id)

    @property
    def agent_kinds(self) -> tuple[str, ...]:
        """The agent kind of each view."""
        return self.agents or (self.agent,) * len(self.views)

    def to_dict(self) -> dict[str, Any]:
        """The config as plain TOML-ready values (tuples become lists), without the sections of the
        other tasks, which this run does not read."""
        data = _plain(dataclasses.asdict(self))
        for unread in self._unread_sections:
            del data[unread]
        return data


@dataclass(frozen=True)
class PaperConfig:
    """One seed of the seed paper's protocol on masked CliffWalking (``task = "paper"``).

    The protocol fixes its runs (:func:`dospcot.paper.protocol_specs`: 26 tabular runs, 37 agents, per
    seed: every agent kind alone under each baseline, homogeneous pairs at three gammas, Expected SARSA
    with the other kinds); a config sets the seed and the hyperparameters every run shares.

    :param name: the run's name: it writes under ``runs/<name>/<stamp>/``.
    :param seed: draws the labelled keys, the exploration streams and the classifiers.
    :param tabular: the hyperparameters every run of the protocol shares.
    """

    name: str = "paper"
    seed: int = 0
    task: Literal["paper"] = "paper"
    tabular: TabularConfig = field(default_factory=TabularConfig)

    def __post_init__(self) -> None:
        _check_name_and_seed(self.name, self.seed)

    def to_dict(self) -> dict[str, Any]:
        """The config as plain TOML-ready values."""
        return _plain(dataclasses.asdict(self))


def _check_name_and_seed(name: str, seed: int) -> None:
    if not name or "/" in name or name.startswith("."):
        raise ConfigError(f"name: must be a plain folder name, got {name!r}")
    if seed < 0:
        raise ConfigError(f"seed: must be >= 0, got {seed}")


def _check_highway_task(highway: HighwayConfig) -> None:
    if highway.env_id == FAST_HIGHWAY_ID:
        check = FastHighwayEnv.check_overrides
    elif highway.env_id in HIGHWAY_ENV_IDS:
        check = partial(try_highway_config, highway.env_id)
    else:
        allowed = ", ".join((*HIGHWAY_ENV_IDS, FAST_HIGHWAY_ID))
        raise ConfigError(f"highway.env_id: unknown task {highway.env_id!r}; allowed: {allowed}")
    try:
        check(highway.config)
    except ValueError as err:
        raise ConfigError(f"highway.config: {err}") from None


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, tuple | list):
        return [_plain(item) for item in value]
    return value


def _presets() -> Any:
    return resources.files("dospcot").joinpath("presets")


def preset_names() -> list[str]:
    """The shipped presets, by name."""
    return sorted(p.name[:-5] for p in _presets().iterdir() if p.name.endswith(".toml"))


def read_config_text(config: str) -> tuple[str, str]:
    """The TOML text of a preset name or a path, and where it came from."""
    if not config.endswith(".toml") and "/" not in config:
        if config not in preset_names():
            names = ", ".join(preset_names())
            raise ConfigError(f"no preset {config!r}; presets: {names} (or a path to a .toml)")
        return _presets().joinpath(f"{config}.toml").read_text(), f"preset {config}"
    path = Path(config)
    if not path.is_file():
        raise ConfigError(f"no config file {config}")
    return path.read_text(), str(path)


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"training.rounds=3"`` -> (["training", "rounds"], 3); values are TOML, bare words strings."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip():
        raise ConfigError(f"--set takes key=value, got {text!r}")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key.strip().split("."), value


def read_config_data(config: str, _seen: tuple[str, ...] = ()) -> dict[str, Any]:
    """The TOML table of a preset or a path, with its ``extends`` chain merged in."""
    if config in _seen:
        raise ConfigError(f"extends: a cycle through {' -> '.join([*_seen, config])}")
    text, origin = read_config_text(config)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{origin} is not valid TOML: {err}") from None
    base = data.pop("extends", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ConfigError(f"extends: expected a preset name or a path, got {base!r}")
    if "/" in base and not Path(base).is_absolute() and "/" in config:
        base = str(Path(config).parent / base)
    return _merge(read_config_data(base, (*_seen, config)), data)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = _merge(merged[key], value)
        else:
            merged[key] = value
    return merged


def load_config(config: str, overrides: Sequence[str] = ()) -> TrainConfig | PaperConfig:
    """Read a preset or a TOML file, apply ``--set`` overrides and validate the result: a
    :class:`PaperConfig` where ``task = "paper"``, else a :class:`TrainConfig`."""
    data = read_config_data(config)
    for override in overrides:
        path, value = parse_override(override)
        if path == ["extends"]:
            raise ConfigError(
                f"--set {override}: extends is read with the file, before any --set; write a .toml "
                f'holding extends = "{value}" and your keys, and pass its path as CONFIG'
            )
        set_key(data, path, value, f"--set {override}")
    return from_mapping(PaperConfig if data.get("task") == "paper" else TrainConfig, data)


def set_key(data: dict[str, Any], path: Sequence[str], value: Any, where: str) -> None:
    """Set the key ``path`` (sections, then the key) of the config table ``data`` to ``value``,
    making missing sections; ``where`` names the override in the error for a key that is no section."""
    table = data
    for part in path[:-1]:
        table = table.setdefault(part, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: {part!r} is not a section")
    table[path[-1]] = value


def from_mapping(cls: type, data: Mapping[str, Any], prefix: str = "") -> Any:
    """Build the dataclass ``cls`` from ``data``, checking every key and type (recursively)."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: expected a table, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    set_elsewhere: dict[str, str] = getattr(cls, "set_elsewhere", {})
    for key in data:
        if key in set_elsewhere:
            raise ConfigError(f"{prefix}{key}: not a config key here; it is set by {set_elsewhere[key]}")
        if key not in fields:
            raise ConfigError(f"unknown key '{prefix}{key}'; allowed: {', '.join(fields)}")
    hints = typing.get_type_hints(cls)
    kwargs = {key: _convert(hints[key], value, f"{prefix}{key}") for key, value in data.items()}
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{prefix.rstrip('.') or 'config'}: {err}") from None


def _convert(hint: Any, value: Any, key: str) -> Any:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if dataclasses.is_dataclass(hint):
        return from_mapping(hint, value, f"{key}.")
    if origin is Literal:
        if value not in args:
            raise ConfigError(f"{key}: {value!r} is not allowed; allowed: {', '.join(map(str, args))}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        return tuple(_convert(args[0], item, key) for item in value)
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{key}: expected a table, got {value!r}")
        return dict(value)
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    raise ConfigError(f"{key}: cannot be set from a config")  # pragma: no cover - a field type we never use
