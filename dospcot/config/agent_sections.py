"""The agents' sections: ``[dqn]`` (every neural agent, stable-baselines3 ``DQN``'s arguments) and
``[tabular_agent]`` (the grid's Q-table agents)."""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any, ClassVar

from dospcot.config.checks import check_at_least, check_positive

DEVICE_PATTERN = re.compile(r"cpu|cuda(:\d+)?")
"""The devices a ``[dqn]`` section may name besides SB3's ``"auto"``."""


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
    # SB3's "auto" takes a GPU wherever torch sees one; a run stays on the CPU unless asked, where it is
    # deterministic for its seed and where networks this small train faster (BENCHMARKS.md, GPU column).
    "device": "cpu",
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


@dataclass(frozen=True)
class DQNConfig:
    """Keyword arguments of every neural agent: each of stable-baselines3 ``DQN``'s that a TOML value
    can hold, under its own name and with its own default except those of :data:`DQN_DEFAULTS`; the
    arguments a ``[dqn]`` section may not hold are :data:`DQN_SET_ELSEWHERE`
    (``tests/test_config.py`` checks both against SB3's signature). Two fields are dospcot's:
    ``net_arch`` and ``cut_windows``.

    :param learning_rate: Adam's step size (a number; SB3 also takes a schedule).
    :param buffer_size: replay capacity, in steps (a run caps it at its total steps).
    :param learning_starts: env steps before the first gradient step.
    :param batch_size: replayed samples per gradient step.
    :param tau: the target network's soft-update coefficient (1: a hard copy).
    :param gamma: the agents' discount (not the co-regularisation weight, ``cotraining.consensus_weight``).
    :param train_freq: env steps between updates.
    :param gradient_steps: gradient steps per update (-1: as many as env steps).
    :param optimize_memory_usage: SB3's memory-efficient replay buffer.
    :param n_steps: the longest n-step window of a replayed sample.
    :param target_update_interval: env steps between target-network updates.
    :param max_grad_norm: the gradient-clipping norm.
    :param stats_window_size: episodes SB3's rollout statistics average over.
    :param device: ``"cpu"``, ``"cuda"``, ``"cuda:<i>"`` or SB3's ``"auto"``.
    :param net_arch: hidden layer widths of the Q-network (SB3's ``policy_kwargs["net_arch"]``).
    :param cut_windows: :class:`~dospcot.policies.ExpectedSarsaDQN`'s own: under the max target
        (``agent = "dqn"``), end n-step windows before the first exploratory action.
    """

    learning_rate: float = DQN_DEFAULTS["learning_rate"]
    buffer_size: int = DQN_DEFAULTS["buffer_size"]
    learning_starts: int = DQN_DEFAULTS["learning_starts"]
    batch_size: int = DQN_DEFAULTS["batch_size"]
    tau: float = 1.0
    gamma: float = DQN_DEFAULTS["gamma"]
    train_freq: int = 4
    gradient_steps: int = 1
    optimize_memory_usage: bool = False
    n_steps: int = 1
    target_update_interval: int = DQN_DEFAULTS["target_update_interval"]
    max_grad_norm: float = 10.0
    stats_window_size: int = 100
    device: str = DQN_DEFAULTS["device"]
    net_arch: tuple[int, ...] = (128, 128)
    cut_windows: bool = True

    set_elsewhere: ClassVar[dict[str, str]] = DQN_SET_ELSEWHERE

    def __post_init__(self) -> None:
        check_at_least(
            self, 1, "buffer_size", "batch_size", "train_freq", "target_update_interval", "n_steps"
        )
        check_at_least(self, 0, "learning_starts")
        check_positive(self, "max_grad_norm", "stats_window_size")
        if self.gradient_steps < 1 and self.gradient_steps != -1:
            raise ValueError(
                f"gradient_steps must be >= 1, or -1 (as many as env steps), got {self.gradient_steps}"
            )
        if self.buffer_size < self.batch_size:
            raise ValueError(
                f"buffer_size must hold a batch (batch_size {self.batch_size}), got {self.buffer_size}"
            )
        if not 0 < self.gamma <= 1 or not 0 < self.tau <= 1:
            raise ValueError(f"gamma and tau must lie in (0, 1], got {self.gamma}, {self.tau}")
        if self.learning_rate <= 0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate}")
        if not self.net_arch or any(width < 1 for width in self.net_arch):
            raise ValueError(
                f"net_arch needs one or more hidden layer widths, each >= 1, got {list(self.net_arch)}"
            )
        if self.device != "auto" and DEVICE_PATTERN.fullmatch(self.device) is None:
            raise ValueError(f"device must be 'cpu', 'cuda', 'cuda:<index>' or 'auto', got {self.device!r}")

    def sb3_kwargs(self) -> dict[str, Any]:
        """The agents' keyword arguments: SB3 ``DQN``'s and ``cut_windows``."""
        kwargs = dataclasses.asdict(self)
        kwargs["policy_kwargs"] = {"net_arch": list(kwargs.pop("net_arch"))}
        return kwargs


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
        check_at_least(self, 1, "batch_size", "train_freq", "gradient_steps", "buffer_size", "n_steps")
        check_at_least(self, 0, "learning_starts")
