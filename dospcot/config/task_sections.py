"""The sections that set up a task: ``[env]`` (the grid world), ``[highway]``, ``[gym]``, and
``[demonstrations]``, which any task may read. Checked without I/O: whatever needs a file, an import
or an env runs in the task's own check step (:mod:`dospcot.tasks`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

from dospcot.config.checks import check_at_least
from dospcot.config.learning_sections import AddedKeys


@dataclass(frozen=True)
class EnvConfig(AddedKeys):
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
    :param episode_end_classes: a reward class the labels show only on keys whose step ended the
        episode (the goal) is given only to such keys, as the ``[gym]`` key of that name does: with a
        goal a tenth of the labels, its pseudo-reward otherwise spreads to ordinary steps, each one a
        reward the agent can collect again and again
        (:func:`dospcot.core.reward_classes.episode_end_class_mask`).
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
    episode_end_classes: bool = False

    added_keys: ClassVar[dict[str, Any]] = {"episode_end_classes": False}

    def __post_init__(self) -> None:
        if not 4 <= self.size <= 256:
            raise ValueError(f"size must lie in [4, 256], got {self.size}")
        check_at_least(self, 0, "layout_seed")
        if not (0 <= self.lava_density < 1 and 0 <= self.wall_density < 1):
            raise ValueError(
                "lava_density and wall_density must lie in [0, 1), got "
                f"{self.lava_density}, {self.wall_density}"
            )
        if self.lava_density + self.wall_density >= 0.9:
            raise ValueError(
                "lava_density + wall_density must stay below 0.9 (the map needs free cells), got "
                f"{self.lava_density + self.wall_density:g}"
            )
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


HIGHWAY_ENV_IDS: tuple[str, ...] = ("highway-fast-v0", "highway-v0", "merge-v0", "roundabout-v0")
"""The highway-env tasks a ``[highway]`` section may name (discrete meta-actions, one controlled
vehicle; the ``highway`` extra)."""
FAST_HIGHWAY_ID = "dospcot/FastHighway-v0"
"""The project's own numpy highway (:class:`dospcot.envs.FastHighwayEnv`)."""
HIGHWAY_ENV_VIEWS: tuple[str, ...] = ("kinematics", "occupancy", "ttc")
"""The views of a highway-env task: highway-env's observation types of those names."""
FAST_HIGHWAY_VIEWS: tuple[str, ...] = ("kinematics", "occupancy")
"""The views of the fast highway, which has no time-to-collision grid."""


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

    @property
    def view_names(self) -> tuple[str, ...]:
        """The views of the task ``env_id``."""
        return FAST_HIGHWAY_VIEWS if self.env_id == FAST_HIGHWAY_ID else HIGHWAY_ENV_VIEWS

    # The sensor adapter reads these of every sensor task's section (dospcot.adapters.sensor_adapter).
    success_return = None
    """A highway episode is a success when it lasts every step (no crash)."""
    max_return = None
    """``R_max`` of the normalised score: ``episode_steps`` (highway-env's rewards are at most 1 a step)."""
    keyed = False
    """Highway states have no key: every step is its own pool sample."""
    read_termination = False
    episode_end_classes = False
    step_class = False
    """A highway's reward is continuous: its quantiles make its classes."""


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
        on, so no pseudo-reward pays a loop (:func:`dospcot.core.reward_classes.episode_end_class_mask`).
        A class also labelled on a step that goes on stays open everywhere.
    :param step_class: where every labelled step whose episode went on pays one reward, below or above
        every other label (MiniGrid's 0 a step), that reward keeps a class of its own, and the other
        labels (the outcomes) share the other ``reward_classes - 1``
        (:meth:`dospcot.core.reward_classes.QuantileRewardClasses.fit`). Without it the bins are the
        labels' quantiles, and where queries fall mostly on episode ends and a goal pays by its time,
        a late goal's pay can share the steps' class, which then pays every step part of a goal.
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
    step_class: bool = False

    infinite_keys: ClassVar[frozenset[str]] = frozenset({"max_return"})
    """Float keys that may be infinite (``inf``: the best return is not known)."""

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

    @property
    def keyed(self) -> bool:
        """Whether the pool holds (state key, action) pairs (``state_key`` is set) instead of steps."""
        return bool(self.state_key)


@dataclass(frozen=True)
class DemonstrationsConfig:
    """The ``[demonstrations]`` section of a config: expert episodes and the roles they play.

    :param episodes: on the grid, expert episodes of value iteration's optimal policy (the first from
        the task's start, the others from random states, :func:`expert_demonstrations`); with
        ``file``, the first this many episodes of the file; 0: none (with ``file``: all of them).
    :param file: a gym task's demonstrations, an ``.npz`` file (:meth:`Demonstrations.save`) holding
        every view of the run; empty: none.
    :param labels: the episodes' rewards are labels. On the grid each demonstrated (s, a) key is
        revealed, to the reward classifiers and to the agents' own steps on it; from a file each
        step joins the classifiers' labelled samples. False: the rewards are not read, so the
        demonstrations reach the agents through the margin loss only.
    :param margin_loss_weight: lambda of the large-margin loss on the demonstrated actions in every
        neural agent's gradient steps (:func:`~dospcot.policies.esarsa_dqn.large_margin_loss`); 0: off.
    :param margin: that loss's margin, in reward units (DQfD's 0.8).
    :param agent: a sensor task's (highway, gym) demonstrations recorded from a saved SB3 agent (a
        ``.zip``): ``episodes`` greedy episodes of it on the run's task, every reward known
        (:func:`record_demonstrations`); empty: none.
    :param agent_algorithm: the SB3 (or sb3-contrib) class that loads ``agent``, e.g. ``DQN``, ``PPO``.
    :param agent_view: the view ``agent`` observes; empty: the run's first view.
    """

    episodes: int = 0
    file: str = ""
    agent: str = ""
    agent_algorithm: str = "DQN"
    agent_view: str = ""
    labels: bool = True
    margin_loss_weight: float = 1.0
    margin: float = 0.8

    def __post_init__(self) -> None:
        if self.episodes < 0:
            raise ValueError(f"episodes must be >= 0, got {self.episodes}")
        if self.file and self.agent:
            raise ValueError("give file or agent, not both: each is a source of demonstrations")
        if self.agent and not self.episodes:
            raise ValueError("agent: set episodes, the number of episodes to record from it")
        if self.margin_loss_weight < 0 or self.margin < 0:
            raise ValueError(
                f"margin_loss_weight and margin must be >= 0, got {self.margin_loss_weight}, {self.margin}"
            )
