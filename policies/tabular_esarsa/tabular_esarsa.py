"""TabularExpectedSarsa: a Q-table over a view's observations, inside stable-baselines3's DQN loop.

For discrete tasks, where every state's view is known in advance, an agent can keep one Q-value per
(observation, action): states that look alike through the agent's view share a row, as they would
for any learner with that sensor. The table is SB3's own ``DQNPolicy`` with no hidden layer on top
of :class:`ViewTableExtractor`, which maps an observation to the one-hot of its row, so the linear
layer's weight (A, U) *is* the table and everything around it is SB3's and
:class:`~dospcot.policies.ExpectedSarsaDQN`'s: ``learn()`` with callbacks and the logger, the
relabelling replay buffer, pace-driven exploration, ``predict``, ``save`` and ``load``.

Only the update differs: instead of a gradient step, each replayed sample moves its entry exactly as
tabular Expected SARSA does, ``Q(s, a) += lr * w * (target - Q(s, a))``, with the target
``r + discount * (1 - done) * sum_a' pi_eps(a' | s') Q(s', a')`` read from the table itself (no
target network). Samples of the same entry in one batch share one step: their weighted TD errors
are averaged, so a batch never moves an entry further than one sample would. Weight-0 samples (a
still unlabelled transition) drive nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from dospcot.policies.esarsa_dqn import ExpectedSarsaDQN, epsilon_greedy_expectation


class ViewTableExtractor(BaseFeaturesExtractor):
    """The one-hot (U,) of an observation's row among the U distinct rows of ``observations``.

    :param observation_space: a 1-D ``Box``.
    :param observations: (n, d) every observation the agent can meet (for a discrete task: the view of
        every state); duplicates share a row.
    :raises ValueError: in ``forward`` on an observation outside ``observations``.
    """

    def __init__(self, observation_space: spaces.Box, observations: np.ndarray) -> None:
        rows = np.unique(np.asarray(observations, dtype=np.float32).reshape(len(observations), -1), axis=0)
        super().__init__(observation_space, features_dim=len(rows))
        self._row_of = {row.tobytes(): i for i, row in enumerate(rows)}

    def rows(self, observations: th.Tensor) -> th.Tensor:
        """(batch,) int64 the table row of each observation (batch, d)."""
        array = np.ascontiguousarray(observations.detach().cpu().numpy(), dtype=np.float32)
        array = array.reshape(len(array), -1)
        try:
            rows = [self._row_of[obs.tobytes()] for obs in array]
        except KeyError:
            unknown = next(obs for obs in array if obs.tobytes() not in self._row_of)
            raise ValueError(
                f"observation {unknown.tolist()} is not among the {self.features_dim} rows of this "
                "tabular agent's table (it was built for another task or view)"
            ) from None
        return th.as_tensor(rows, dtype=th.int64, device=observations.device)

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return F.one_hot(self.rows(observations), self.features_dim).to(observations.dtype)


class TabularExpectedSarsa(ExpectedSarsaDQN):
    """Tabular Expected SARSA (or Q-learning, ``target="q"``) with SB3's DQN around it.

    :param policy: ``"MlpPolicy"`` (the table is SB3's ``DQNPolicy`` over :class:`ViewTableExtractor`).
    :param env: a task with a 1-D ``Box`` observation and discrete actions.
    :param observations: (n, d) every observation the agent can meet; the table has one row per
        distinct one.
    :param learning_rate: the step size alpha in (0, 1] (a float or an SB3 schedule).
    :param kwargs: :class:`~dospcot.policies.ExpectedSarsaDQN`'s (``target``, exploration, buffer,
        ``batch_size``, ``train_freq``, ``gradient_steps``, ...). The network is the table:
        ``policy_kwargs`` may not be given.

    Saved zips load with ``TabularExpectedSarsa.load`` or ``stable_baselines3.DQN.load`` wherever
    dospcot is importable (the extractor class is dospcot's), and predict exactly as the table does.
    """

    def __init__(
        self,
        policy: Any,
        env: Any,
        observations: np.ndarray | None = None,
        *,
        learning_rate: Any = 0.5,
        **kwargs: Any,
    ) -> None:
        if kwargs.get("_init_setup_model", True):  # not when load() rebuilds a saved agent
            if observations is None:
                raise ValueError("a tabular agent needs observations: every observation it can meet")
            if "policy_kwargs" in kwargs:
                raise ValueError("a tabular agent's network is its table: policy_kwargs cannot be set")
            if isinstance(learning_rate, float | int) and not 0 < learning_rate <= 1:
                raise ValueError(f"learning_rate (alpha) must lie in (0, 1], got {learning_rate}")
            kwargs["policy_kwargs"] = {
                "net_arch": [],
                "features_extractor_class": ViewTableExtractor,
                "features_extractor_kwargs": {"observations": np.asarray(observations, dtype=np.float32)},
            }
        super().__init__(policy, env, learning_rate=learning_rate, **kwargs)

    def _setup_model(self) -> None:
        super()._setup_model()
        with th.no_grad():  # an all-zero table; the bias stays 0, so Q(s, a) is the weight's entry
            for parameter in self.policy.parameters():
                parameter.zero_()

    @property
    def q_table(self) -> th.Tensor:
        """(A, U) the table: ``q_table[a, row]`` is Q(row, a)."""
        return self.q_net.q_net[0].weight

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        alpha = float(self.lr_schedule(self._current_progress_remaining))
        self.logger.record("train/learning_rate", alpha)
        extractor: ViewTableExtractor = self.q_net.features_extractor
        table = self.q_table.data
        flat_table = table.view(-1)
        n_rows = table.shape[1]
        errors = []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            weights = getattr(data, "weights", None)  # SB3's own buffers carry none: every sample counts
            weights = th.ones_like(data.rewards).flatten() if weights is None else weights.flatten()
            if not weights.any():
                continue  # nothing labelled in this batch: no update
            discounts = data.discounts.flatten() if data.discounts is not None else self.gamma
            rows = extractor.rows(data.observations)
            next_q = table[:, extractor.rows(data.next_observations)].T
            if self.target == "q":
                next_value = next_q.max(dim=1).values
            else:
                next_value = epsilon_greedy_expectation(next_q, next_q, self.exploration_rate)
            target = data.rewards.flatten() + (1 - data.dones.flatten()) * discounts * next_value
            entry = data.actions.flatten().long() * n_rows + rows
            delta = target - flat_table[entry]
            step = th.zeros_like(flat_table).index_add_(0, entry, weights * delta)
            count = th.zeros_like(flat_table).index_add_(0, entry, th.ones_like(delta))
            flat_table.add_(alpha * step / count.clamp(min=1.0))
            errors.append(float((weights * delta.square()).sum() / weights.sum()))
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if errors:
            self.logger.record("train/loss", 0.5 * float(np.mean(errors)))
