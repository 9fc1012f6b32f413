"""The agents of a co-training run, one per view, built from the run's config: their kind's TD target,
their relabelling replay buffer's arguments and the exploration they start from
(:class:`~dospcot.core.sb3_round.CoTrainingRun` builds them with :func:`make_agent`)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from dospcot.core.self_paced import NUMERICS
from dospcot.envs.finite_check import FiniteCheckWrapper
from dospcot.policies import ExpectedSarsaDQN, RewardTable, TabularExpectedSarsa
from dospcot.seeding import agent_seed

if TYPE_CHECKING:
    from dospcot.config.run_configs import TrainConfig

AGENT_TARGETS = {"esarsa_dqn": "expected_sarsa", "dqn": "q", "tabular": "expected_sarsa"}
"""Agent kinds and their TD target: ExpectedSarsaDQN with its Expected-SARSA target or DQN's max target,
and the tabular Expected-SARSA agent."""


def relabelling_kwargs(method: str, table: RewardTable) -> dict[str, Any]:
    """The relabelling replay buffer's arguments for a method: co-training and the reward-model peer
    read the reward table, masked-zero counts masked rewards as 0, the rest weigh masked steps 0."""
    return {
        "reward_table": table if method in ("dospcot", "reward-model") else None,
        "masked_reward": "zero" if method == "masked-zero" else "ignore",
    }


def make_agent(
    env: gym.Env,
    k: int,
    kind: str,
    view: str,
    cfg: TrainConfig,
    buffer_kwargs: dict[str, Any],
    observations: np.ndarray | None = None,
) -> ExpectedSarsaDQN:
    """Agent ``k`` of a run, at pace 0, on ``env`` checked for non-finite values.

    :param observations: (S, d) the view of every state, which a ``tabular`` agent's table is built
        over; None for a task whose observations are not known in advance.
    """
    env = FiniteCheckWrapper(env, f"{type(env.unwrapped).__name__} (agent {k}, view {view})")
    training = cfg.training
    common = dict(
        target=AGENT_TARGETS[kind],
        seed=agent_seed(cfg.seed, k),
        exploration_initial_eps=training.eps_start,
        exploration_final_eps=training.eps_end,
        replay_buffer_kwargs=buffer_kwargs,
    )
    if kind == "tabular":
        if observations is None:
            raise ValueError(
                "agent kind 'tabular' needs a discrete task whose observations are known in advance "
                "(a grid world); use esarsa_dqn or dqn"
            )
        kwargs = dataclasses.asdict(cfg.tabular_agent)
        # Steps beyond a run's total never enter the buffer (TrainConfig.buffer_size, as for the others).
        kwargs["buffer_size"] = min(kwargs["buffer_size"], training.total_steps)
        agent = TabularExpectedSarsa("MlpPolicy", env, observations, **common, **kwargs)
    else:
        kwargs = {**cfg.dqn.sb3_kwargs(), "buffer_size": cfg.buffer_size}
        numerics = NUMERICS[cfg.cotraining.numerics]
        demos = cfg.demonstrations
        agent = ExpectedSarsaDQN(
            "MlpPolicy",
            env,
            **common,
            **kwargs,
            demo_margin=demos.margin,
            demo_loss_weight=demos.margin_loss_weight,
            sparse_inputs=numerics.sparse_inputs,
            fused_adam=numerics.fused_adam,
        )
    agent.learning_starts = max(agent.learning_starts, training.collect_only_steps)
    agent.set_pace(0.0)
    return agent
