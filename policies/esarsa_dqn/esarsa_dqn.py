"""ExpectedSarsaDQN: stable-baselines3's DQN with an Expected-SARSA target, exploration driven by the
co-trainer's pace, and self-paced weights from a relabelling replay buffer.

TD target: ``r + discount * (1 - done) * sum_a pi_eps(a | s') Q_target(s', a)``, where pi_eps is
epsilon-greedy around a greedy action at s' and eps is the agent's current exploration rate.

Which network picks the greedy action (``greedy``) is a trade of speed against bias:

- ``"target"`` (default): the target network's own greedy action, so the expectation is
  ``eps * mean_a Q_target(s', a) + (1 - eps) * max_a Q_target(s', a)`` and needs only the target
  forward pass DQN makes anyway: ExpectedSarsaDQN runs at DQN's speed. At eps = 0 it is DQN's max
  target, with its overestimation.
- ``"online"``: the online network's greedy action (the greedy mass split across tied maxima), as
  Double DQN does, which keeps the target from chasing the target net's own overestimates; at
  eps = 0 it is the Double-DQN target. It costs an online forward over s' as well: one forward over
  s and s' together, the s' half detached, which is a forward and backward twice as wide.

``target="q"`` gives SB3's max target exactly, for ablations. With ``n_steps`` > 1 the relabelling
buffer returns n-step windows and their discounts (:class:`RelabellingReplayBuffer`). Under the max
target a window ends before the first exploratory action after its first step (``cut_windows``, on
by default), as Watkins's Q(lambda) does: the max target values the greedy policy, and an n-step
return that follows random actions values the eps-greedy one instead. In a grid with -100 lava, the
random steps into lava inside windows drag every value near lava down by several units, more than
the gaps between actions far from the goal, and the greedy policy loops. An action counts as
exploratory when it differs from the online network's greedy action at the time it was taken (the
forward pass that picks the greedy action also flags it, so flagging costs no extra pass). The
Expected-SARSA target values the eps-greedy policy itself, so its windows stay whole.

The loss is the weighted mean of the per-sample Huber loss, ``sum_i w_i l_i / sum_i w_i``; weight-0
samples drive nothing. With demonstrations (:meth:`ExpectedSarsaDQN.set_demonstrations`) every
gradient step adds ``demo_loss_weight`` times DQfD's large-margin loss (:func:`large_margin_loss`)
on a minibatch of demonstrated (state, action) pairs, which pulls the demonstrated action's value
above every other action's by a margin.

With ``sparse_inputs`` on an observation space of 0s and 1s (a ``Box(0, 1)`` of uint8: one-hot and
indicator views), the Q-networks' first layer sums the weight rows of the inputs that are on
(:class:`~dospcot.policies.esarsa_dqn.sparse_inputs.SparseInputLinear`), the same values and dense
gradients as the stock layer's product over every input, up to float rounding. ``fused_adam`` steps
Adam in one fused kernel (``torch.optim.Adam(fused=True)``): the same update, up to rounding, in one
pass over each parameter instead of one per operation.

The saved zip holds the stock ``DQNPolicy`` and nothing of dospcot, so
``stable_baselines3.DQN.load`` reads it in a process that never imported dospcot: a sparse first
layer saves its weight, and Adam's moments of it, in ``nn.Linear``'s layout.
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.common.utils import polyak_update
from torch.nn.utils import clip_grads_with_norm_, get_total_norm

from dospcot.policies.esarsa_dqn.buffers import RelabellingReplayBuffer, _binary
from dospcot.policies.esarsa_dqn.sparse_inputs import (
    own_optimizer_state,
    sparsify_first_layer,
    stock_optimizer_state,
)

Target = Literal["expected_sarsa", "q"]
TARGETS: tuple[str, ...] = ("expected_sarsa", "q")
Greedy = Literal["target", "online"]
GREEDY: tuple[str, ...] = ("target", "online")


def epsilon_greedy_expectation(online_q: th.Tensor, target_q: th.Tensor, eps: float) -> th.Tensor:
    """``sum_a pi_eps(a | s') Q_target(s', a)`` with pi_eps epsilon-greedy around argmax of ``online_q``.

    :param online_q: (batch, A) online-network values, which pick the greedy action(s).
    :param target_q: (batch, A) target-network values being averaged.
    :param eps: exploration rate in [0, 1].
    :return: (batch,) expected values.
    """
    ties = (online_q == online_q.max(dim=1, keepdim=True).values).to(target_q.dtype)
    greedy = (ties * target_q).sum(dim=1) / ties.sum(dim=1)
    return eps * target_q.mean(dim=1) + (1.0 - eps) * greedy


def weighted_huber_loss(
    current: th.Tensor, target: th.Tensor, weights: th.Tensor, total: float | None = None
) -> th.Tensor:
    """``sum_i w_i huber(current_i, target_i) / sum_i w_i`` (0 when every weight is 0).

    :param current: (batch, 1) estimates; ``target``: (batch, 1); ``weights``: (batch, 1) in [0, 1].
    :param total: ``sum_i w_i`` when the caller has it already.
    """
    per_sample = F.smooth_l1_loss(current, target, reduction="none")
    total = float(weights.sum()) if total is None else total
    return th.dot(per_sample.view(-1), weights.view(-1)) / max(total, 1e-12)


def large_margin_loss(q: th.Tensor, expert_actions: th.Tensor, margin: float) -> th.Tensor:
    """DQfD's supervised loss (Hester et al., 2018): ``mean_i max_a [Q(s_i, a) + l(a_i, a)] - Q(s_i, a_i)``
    with ``l(a_i, a) = margin`` for ``a != a_i`` and 0 for the expert's action ``a_i``. It is 0 exactly
    when every demonstrated action's value leads every other by at least ``margin``.

    :param q: (batch, A) online values at the demonstrated states.
    :param expert_actions: (batch,) int64, the demonstrated actions.
    :param margin: the margin, >= 0, in reward units.
    """
    expert = expert_actions.long().view(-1, 1)
    penalty = th.full_like(q, margin).scatter(1, expert, 0.0)
    return ((q + penalty).max(dim=1).values - q.gather(1, expert).view(-1)).mean()


def _check_eps(name: str, value: float) -> float:
    value = float(value)
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1], got {value}")
    return value


class ExpectedSarsaDQN(DQN):
    """DQN with an Expected-SARSA target and pace-driven exploration (see the module docstring).

    :param policy: ``"MlpPolicy"``, ``"CnnPolicy"``, ``"MultiInputPolicy"`` or a ``DQNPolicy`` class.
    :param env: the environment (discrete actions only).
    :param target: ``"expected_sarsa"`` (default) or ``"q"`` (SB3's max target).
    :param greedy: which network picks pi_eps's greedy action, ``"target"`` (default) or ``"online"``
        (see the module docstring).
    :param cut_windows: with ``target="q"`` and ``n_steps`` > 1, end n-step windows before the first
        exploratory action (see the module docstring); False gives SB3's uncut n-step returns.
    :param exploration_horizon: env steps over which eps decays from ``exploration_initial_eps`` to
        ``exploration_final_eps`` (within ``exploration_fraction`` of them) when no co-trainer sets a
        pace. Counted in total steps, so the schedule continues across ``learn()`` calls; None takes
        the ``total_timesteps`` of the first ``learn()``.
    :param demo_margin: the large-margin loss's margin (DQfD's 0.8), in reward units.
    :param demo_loss_weight: lambda of the large-margin loss in every gradient step's loss, once
        demonstrations are set (:meth:`set_demonstrations`).
    :param sparse_inputs: on an observation space of 0s and 1s with ``"MlpPolicy"``, the Q-networks'
        first layer sums the weight rows of the inputs that are on (see the module docstring);
        elsewhere it has no effect.
    :param fused_adam: Adam (the policy's default optimiser) steps in one fused kernel.
    :param kwargs: every other argument of ``stable_baselines3.DQN``. ``replay_buffer_class``
        defaults to :class:`RelabellingReplayBuffer`.
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = DQN.policy_aliases
    _explored: np.ndarray | None = None
    """(n_envs,) whether the actions just sampled were exploratory, when windows are cut."""
    _greedy: np.ndarray | None = None
    """(n_envs,) the online network's greedy actions at ``_last_obs`` while an action is sampled."""
    _demo_obs: th.Tensor | None = None
    """(N, d) the demonstrated states, as this agent observes them (:meth:`set_demonstrations`)."""
    _demo_actions: th.Tensor | None = None
    """(N,) the demonstrated actions."""
    sparse_inputs: bool = False
    fused_adam: bool = False
    _sparse_weights: tuple[th.nn.Parameter, ...] = ()
    """The online Q-network's sparse first-layer weight, when it has one (the optimiser's)."""
    _clipped: list[th.nn.Parameter]
    """The policy's parameters in its order, listed once: those whose gradients a step clips."""

    def __init__(
        self,
        policy: str | type[BasePolicy],
        env: Any,
        *,
        target: Target = "expected_sarsa",
        greedy: Greedy = "target",
        cut_windows: bool = True,
        exploration_horizon: int | None = None,
        demo_margin: float = 0.8,
        demo_loss_weight: float = 1.0,
        sparse_inputs: bool = False,
        fused_adam: bool = False,
        **kwargs: Any,
    ) -> None:
        if target not in TARGETS:
            raise ValueError(f"target must be one of {TARGETS}, got {target!r}")
        if greedy not in GREEDY:
            raise ValueError(f"greedy must be one of {GREEDY}, got {greedy!r}")
        action_space = getattr(env, "action_space", None)
        if action_space is not None and not isinstance(action_space, spaces.Discrete):
            raise ValueError(f"ExpectedSarsaDQN needs a Discrete action space, got {action_space}")
        for name in ("exploration_initial_eps", "exploration_final_eps"):
            if name in kwargs:
                _check_eps(name, kwargs[name])
        if exploration_horizon is not None and exploration_horizon < 1:
            raise ValueError(f"exploration_horizon must be a positive step count, got {exploration_horizon}")
        if demo_margin < 0 or demo_loss_weight < 0:
            raise ValueError(
                f"demo_margin and demo_loss_weight must be >= 0, got {demo_margin} and {demo_loss_weight}"
            )
        kwargs.setdefault("replay_buffer_class", RelabellingReplayBuffer)
        self.demo_margin = float(demo_margin)
        self.demo_loss_weight = float(demo_loss_weight)
        self.target = target
        self.greedy = greedy
        self.cut_windows = cut_windows
        self.exploration_horizon = exploration_horizon
        self.sparse_inputs = bool(sparse_inputs)
        self.fused_adam = bool(fused_adam)
        self.pace: float | None = None
        super().__init__(policy, env, **kwargs)

    def set_pace(self, pace: float) -> None:
        """Drive exploration by the co-trainer's pace p in [0, 1]: eps = initial + (final - initial) * p."""
        pace = float(pace)
        if not 0.0 <= pace <= 1.0:
            raise ValueError(f"pace must lie in [0, 1], got {pace}")
        self.pace = pace
        self.exploration_rate = self._scheduled_eps()

    def set_demonstrations(self, observations: np.ndarray | None, actions: np.ndarray | None) -> None:
        """Demonstrated (state, action) pairs for the large-margin loss; None clears them.

        :param observations: (N, *observation shape), the states as this agent observes them.
        :param actions: (N,) ints, the actions demonstrated there.
        """
        if observations is None or actions is None or len(actions) == 0:
            self._demo_obs = self._demo_actions = None
            return
        observations, actions = np.asarray(observations), np.asarray(actions)
        shape = self.observation_space.shape
        if observations.shape != (len(actions), *shape) or actions.ndim != 1:
            raise ValueError(
                f"set_demonstrations needs observations (N, {', '.join(map(str, shape))}) and actions "
                f"(N,), got {observations.shape} and {actions.shape}"
            )
        n_actions = int(self.action_space.n)  # type: ignore[attr-defined]
        if actions.min() < 0 or actions.max() >= n_actions:
            raise ValueError(
                f"demonstrated actions must lie in [0, {n_actions}), got {actions.min()} to {actions.max()}"
            )
        self._demo_obs = th.as_tensor(observations, dtype=th.float32, device=self.device)
        self._demo_actions = th.as_tensor(actions, dtype=th.int64, device=self.device)

    @property
    def n_demonstrations(self) -> int:
        """The demonstrated (state, action) pairs the large-margin loss reads (0: none)."""
        return 0 if self._demo_actions is None else len(self._demo_actions)

    def _demo_loss(self, batch_size: int) -> th.Tensor | None:
        """``demo_loss_weight`` x the large-margin loss on ``batch_size`` demonstrated pairs drawn from
        numpy's global stream (which SB3 seeds, as its buffers' draws); None without demonstrations."""
        if self._demo_obs is None or self._demo_actions is None or self.demo_loss_weight == 0.0:
            return None
        index = th.as_tensor(np.random.randint(0, len(self._demo_actions), size=batch_size))  # noqa: NPY002
        q = self.q_net(self._demo_obs[index])
        return self.demo_loss_weight * large_margin_loss(q, self._demo_actions[index], self.demo_margin)

    def _scheduled_eps(self) -> float:
        initial, final = self.exploration_initial_eps, self.exploration_final_eps
        if self.pace is not None:
            return initial + (final - initial) * self.pace
        # SB3's LinearSchedule, but over total steps rather than the current learn() call's progress.
        progress = self.num_timesteps / ((self.exploration_horizon or 1) * self.exploration_fraction)
        return final if progress >= 1.0 else initial + progress * (final - initial)

    def _setup_learn(self, total_timesteps: int, *args: Any, **kwargs: Any):
        if self.exploration_horizon is None:
            self.exploration_horizon = int(total_timesteps)
        return super()._setup_learn(total_timesteps, *args, **kwargs)

    def _setup_model(self) -> None:
        n_steps = self.n_steps
        if n_steps > 1 and issubclass(self.replay_buffer_class, RelabellingReplayBuffer):
            # SB3 sets n-step returns up for its own buffer only (and warns otherwise): pass them on.
            self.replay_buffer_kwargs = {**self.replay_buffer_kwargs, "n_steps": n_steps, "gamma": self.gamma}
            self.n_steps = 1
        super()._setup_model()
        self.n_steps = n_steps
        self._setup_fast_paths()
        self._clipped = list(self.policy.parameters())
        # DQN's _on_step reads eps from this schedule, which would restart at every learn().
        self.exploration_schedule = self._exploration_schedule

    def _setup_fast_paths(self) -> None:
        """Give both Q-networks a sparse first layer (``sparse_inputs``, on a space of 0s and 1s under
        SB3's MLP) and build the optimiser again over the online network, fused if ``fused_adam``."""
        policy = self.policy
        self._sparse_weights = ()
        mlp = isinstance(policy.q_net.features_extractor, FlattenExtractor)
        if self.sparse_inputs and mlp and _binary(self.observation_space):
            online = sparsify_first_layer(policy.q_net.q_net)
            sparsify_first_layer(policy.q_net_target.q_net)
            self._sparse_weights = () if online is None else (online.weight_t,)
        if not self._sparse_weights and not self.fused_adam:
            return
        kwargs = dict(policy.optimizer_kwargs)
        if self.fused_adam:
            if policy.optimizer_class not in (th.optim.Adam, th.optim.AdamW):
                raise ValueError(f"fused_adam needs Adam or AdamW, got {policy.optimizer_class.__name__}")
            kwargs["fused"] = True
        # SB3's DQNPolicy._build makes its optimiser the same way, before the layer changed.
        policy.optimizer = policy.optimizer_class(policy.q_net.parameters(), lr=self.lr_schedule(1), **kwargs)

    def get_parameters(self) -> dict[str, dict]:
        """SB3's parameters to save; a sparse first layer's Adam moments in ``nn.Linear``'s layout, as
        its weight is (stock SB3 loads both)."""
        params = super().get_parameters()
        if self._sparse_weights:
            optimizer, weights = self.policy.optimizer, list(self._sparse_weights)
            params["policy.optimizer"] = stock_optimizer_state(optimizer, weights)
        return params

    def set_parameters(self, load_path_or_dict: Any, exact_match: bool = True, device: Any = "auto") -> None:
        """SB3's ``set_parameters``; a sparse first layer's Adam moments back into its own layout."""
        super().set_parameters(load_path_or_dict, exact_match, device)
        if self._sparse_weights:
            own_optimizer_state(self.policy.optimizer, list(self._sparse_weights))

    def _exploration_schedule(self, _progress_remaining: float) -> float:
        return self._scheduled_eps()

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        flag = self.cut_windows and self.target == "q" and self.n_steps > 1
        if self.num_timesteps < learning_starts and not flag:  # uniform warm-up draws: no forward pass
            return super()._sample_action(learning_starts, action_noise, n_envs)
        # The greedy actions from the Q-network directly. policy.predict switches the network to eval
        # mode and reshapes on every call, which costs more than the forward pass of a small network;
        # SB3's collect_rollouts has switched it once already, for every step it collects.
        with th.no_grad():
            greedy = self.q_net(self.policy.obs_to_tensor(self._last_obs)[0]).argmax(dim=1).cpu().numpy()
        self._greedy = greedy  # predict() takes it rather than making the same forward pass again
        try:
            action, buffer_action = super()._sample_action(learning_starts, action_noise, n_envs)
        finally:
            self._greedy = None
        if flag:
            self._explored = np.asarray(buffer_action).reshape(n_envs) != greedy
        return action, buffer_action

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """SB3 DQN's eps-greedy ``predict``; while collecting, the greedy actions of ``_last_obs`` come
        from the forward pass :meth:`_sample_action` made (which also flags exploration, where windows
        are cut)."""
        if self._greedy is None or deterministic:
            return super().predict(observation, state, episode_start, deterministic)
        # DQN.predict's draw from the global stream SB3 seeds: one uniform for the whole batch, then a
        # random action per env, so a run makes the same draws as with DQN.predict.
        if np.random.rand() < self.exploration_rate:  # noqa: NPY002
            return np.array([self.action_space.sample() for _ in range(len(self._greedy))]), state
        return self._greedy, state

    def _store_transition(
        self,
        replay_buffer: Any,
        buffer_action: np.ndarray,
        new_obs: Any,
        reward: np.ndarray,
        dones: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        if self._explored is not None:  # the relabelling buffer reads it (RelabellingReplayBuffer)
            for info, explored in zip(infos, self._explored, strict=True):
                info["explored"] = bool(explored)
        super()._store_transition(replay_buffer, buffer_action, new_obs, reward, dones, infos)

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses, margin_losses = [], []
        for _ in range(gradient_steps):
            data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            weights = getattr(data, "weights", None)
            if weights is None:
                weights = th.ones_like(data.rewards)
            total = float(weights.sum())
            demo_loss = self._demo_loss(batch_size)
            if total == 0.0 and demo_loss is None:
                continue  # nothing labelled in this batch: no update
            current_q, next_value = self._current_and_next_value(data.observations, data.next_observations)
            with th.no_grad():
                discounts = data.discounts if data.discounts is not None else self.gamma
                target_q = data.rewards + (1 - data.dones) * discounts * next_value.reshape(-1, 1)
            current_q = th.gather(current_q, dim=1, index=data.actions.long())
            loss = weighted_huber_loss(current_q, target_q, weights, total)
            losses.append(loss.item())
            if demo_loss is not None:
                margin_losses.append(demo_loss.item())
                loss = loss + demo_loss
            self.policy.optimizer.zero_grad()
            loss.backward()
            self._clip_gradients()
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        if losses:
            self.logger.record("train/loss", float(np.mean(losses)))
        if margin_losses:  # weighted, as it enters the loss
            self.logger.record("train/margin_loss", float(np.mean(margin_losses)))

    def _clip_gradients(self) -> None:
        """SB3's ``clip_grad_norm_(policy.parameters(), max_grad_norm)`` in the same arithmetic, without
        the work that changes nothing: the parameters are listed once, and where the coefficient clamps
        to 1 (the norm within the bound, most steps) the gradients are not multiplied by it."""
        norm = get_total_norm([p.grad for p in self._clipped if p.grad is not None])
        if not bool(self.max_grad_norm / (norm + 1e-6) >= 1.0):  # a NaN norm is multiplied in, as there
            clip_grads_with_norm_(self._clipped, self.max_grad_norm, norm)

    def update(self, gradient_steps: int) -> None:
        """``gradient_steps`` of :meth:`train` on the replay buffer as it reads now, without acting: the
        co-trainer's policy-update phase, which fits the agent to the reward table a round just wrote.

        The target network is synced as often as during ``learn()``: every
        ``target_update_interval * gradient_steps / train_freq`` gradient steps (and after the last).
        """
        for chunk in self.update_chunks(gradient_steps):
            self.train(chunk, self.batch_size)
            polyak_update(self.q_net.parameters(), self.q_net_target.parameters(), self.tau)
            polyak_update(self.batch_norm_stats, self.batch_norm_stats_target, 1.0)

    def update_chunks(self, gradient_steps: int) -> list[int]:
        """:meth:`update`'s ``gradient_steps``, cut where the target network syncs: chunks of
        ``target_update_interval * gradient_steps / train_freq`` steps (the last may be shorter); none
        while the replay buffer is empty."""
        if gradient_steps < 0:
            raise ValueError(f"gradient_steps must be >= 0, got {gradient_steps}")
        if gradient_steps == 0 or self.replay_buffer is None or self.replay_buffer.size() == 0:
            return []
        per_env_step = self.gradient_steps / self.train_freq.frequency
        between_syncs = max(1, round(self.target_update_interval * per_env_step))
        return [min(between_syncs, gradient_steps - done) for done in range(0, gradient_steps, between_syncs)]

    def _current_and_next_value(self, obs: th.Tensor, next_obs: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """(batch, A) online values at s, with gradient, and (batch,) the bootstrap value at s'."""
        with th.no_grad():
            next_q_target = self.q_net_target(next_obs)
        if self.target == "q":
            return self.q_net(obs), next_q_target.max(dim=1).values
        if self.greedy == "target":
            # Around the target net's own greedy action the greedy mass lands on its max, ties or not.
            greedy_value = next_q_target.max(dim=1).values
            expected = th.lerp(greedy_value, next_q_target.mean(dim=1), self.exploration_rate)
            return self.q_net(obs), expected
        # One online forward over s and s' together; only the s half carries a gradient.
        both = self.q_net(th.cat([obs, next_obs]))
        current_q, next_online = both[: len(obs)], both[len(obs) :].detach()
        return current_q, epsilon_greedy_expectation(next_online, next_q_target, self.exploration_rate)

    def _excluded_save_params(self) -> list[str]:
        # The buffer class lives in dospcot: keep it out of the zip so plain DQN.load works anywhere.
        # The schedule is a bound method of this model; _setup_model binds it again on load.
        return [
            *super()._excluded_save_params(),
            "replay_buffer_class",
            "replay_buffer_kwargs",
            "exploration_schedule",
            "_explored",
            "_greedy",
            "_demo_obs",
            "_demo_actions",
            "_sparse_weights",
            "_clipped",
        ]
