"""One gradient step of S members' :class:`~dospcot.policies.ExpectedSarsaDQN` at once.

Each member is an ExpectedSarsaDQN agent of its own seed: its online and target networks are slices of
two :class:`StackedQNetwork`, its Adam state a slice of one :class:`StackedAdam`. A step reads a batch
per member, stacked on a leading axis, and does what ``ExpectedSarsaDQN.train`` does for one batch:

1. the bootstrap value at s' under the member's target (``"expected_sarsa"`` around the target or the
   online network's greedy action, at the member's own exploration rate; or ``"q"``, the max);
2. the weighted Huber loss ``sum_i w_i l_i / sum_i w_i`` of each member, plus, with demonstrations,
   the large-margin loss;
3. the gradient of the members' summed losses, which is each member's own gradient on its slice;
4. gradient-norm clipping per member (``max_grad_norm`` over that member's parameters, as
   ``clip_grad_norm_`` over one policy's);
5. the Adam step of every member whose batch holds a labelled sample (or a demonstration); a member
   with neither skips the update, as ``train`` does.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch as th
import torch.nn.functional as F

from dospcot.policies.esarsa_dqn import ExpectedSarsaDQN, WeightedReplayBufferSamples
from dospcot.policies.esarsa_dqn.esarsa_dqn import GREEDY, TARGETS, Greedy, Target
from dospcot.policies.stacked_esarsa.stacked_adam import StackedAdam
from dospcot.policies.stacked_esarsa.stacked_q_network import StackedQNetwork, linear_layers


class StackedExpectedSarsa:
    """S members' online and target Q-networks and their optimizer.

    :param q_net: the members' online networks.
    :param q_net_target: their target networks.
    :param learning_rate: Adam's learning rate (constant, as the presets' DQN).
    :param max_grad_norm: each member's gradient-norm clip.
    :param target: ``"expected_sarsa"`` or ``"q"`` (:class:`~dospcot.policies.ExpectedSarsaDQN`).
    :param greedy: ``"target"`` or ``"online"``: which network picks the greedy action at s'.
    :param demo_margin: the large-margin loss's margin, in reward units.
    :param demo_loss_weight: the large-margin loss's weight in each member's loss.
    """

    def __init__(
        self,
        q_net: StackedQNetwork,
        q_net_target: StackedQNetwork,
        learning_rate: float,
        max_grad_norm: float,
        target: Target = "expected_sarsa",
        greedy: Greedy = "target",
        demo_margin: float = 0.8,
        demo_loss_weight: float = 1.0,
    ) -> None:
        if target not in TARGETS or greedy not in GREEDY:
            raise ValueError(
                f"target must be one of {TARGETS} and greedy one of {GREEDY}, got {target}, {greedy}"
            )
        self.q_net, self.q_net_target = q_net, q_net_target
        self.optimizer = StackedAdam(q_net.parameters(), learning_rate)
        self.max_grad_norm = float(max_grad_norm)
        self.target, self.greedy = target, greedy
        self.demo_margin, self.demo_loss_weight = float(demo_margin), float(demo_loss_weight)

    @classmethod
    def from_agents(cls, agents: Sequence[ExpectedSarsaDQN]) -> StackedExpectedSarsa:
        """The members ``agents`` (one per seed, one config): their networks' weights and their Adams'
        states copied, their settings read from the first."""
        first = agents[0]
        learner = cls(
            StackedQNetwork.from_q_networks([a.q_net for a in agents]),
            StackedQNetwork.from_q_networks([a.q_net_target for a in agents]),
            first.lr_schedule(1.0),
            first.max_grad_norm,
            first.target,
            first.greedy,
            first.demo_margin,
            first.demo_loss_weight,
        )
        stacked = learner.q_net
        for member, agent in enumerate(agents):
            adam = agent.policy.optimizer.state
            for i, layer in enumerate(linear_layers(agent.q_net)):
                for mine, theirs in ((stacked.weights[i], layer.weight), (stacked.biases[i], layer.bias)):
                    state = adam.get(theirs)
                    if state:  # a member that has taken no step yet has none
                        learner.optimizer.set_member(
                            mine, member, float(state["step"]), state["exp_avg"], state["exp_avg_sq"]
                        )
        return learner

    def sync_target(self) -> None:
        """Copy every member's online weights into its target network (``tau = 1``)."""
        self.q_net_target.copy_from(self.q_net)

    def train_step(
        self,
        data: WeightedReplayBufferSamples,
        exploration_rate: th.Tensor,
        gamma: float,
        demonstrations: tuple[th.Tensor, th.Tensor] | None = None,
    ) -> tuple[th.Tensor, th.Tensor]:
        """One gradient step of every member on its batch.

        :param data: each field (S, B, ...) (``discounts`` None: every sample's discount is ``gamma``).
        :param exploration_rate: (S,) each member's eps, which weighs the Expected-SARSA target.
        :param gamma: the discount of one-step samples.
        :param demonstrations: (S, B_d, *obs shape) states and (S, B_d) actions, each member's minibatch
            of demonstrated pairs; None: no large-margin loss.
        :return: (S,) each member's weighted Huber loss (0 where it skipped), and (S,) bool, which members
            updated.
        """
        current_q, next_value = self._current_and_next_value(
            data.observations, data.next_observations, exploration_rate
        )
        with th.no_grad():
            discounts = data.discounts if data.discounts is not None else gamma
            target_q = data.rewards + (1 - data.dones) * discounts * next_value.unsqueeze(-1)
        current_q = th.gather(current_q, dim=2, index=data.actions.long())
        weights = data.weights
        total = weights.sum(dim=(1, 2))
        per_sample = F.smooth_l1_loss(current_q, target_q, reduction="none")
        losses = (per_sample * weights).sum(dim=(1, 2)) / total.clamp_min(1e-12)
        loss = losses
        active = total > 0
        if demonstrations is not None and self.demo_loss_weight != 0.0:
            loss = loss + self.demo_loss_weight * self._margin_losses(*demonstrations)
            active = th.ones_like(active)
        for p in self.q_net.parameters():
            p.grad = None
        loss.sum().backward()
        self._clip_gradients()
        self.optimizer.step(active)
        return th.where(active, losses.detach(), th.zeros_like(losses)), active

    def _current_and_next_value(
        self, obs: th.Tensor, next_obs: th.Tensor, exploration_rate: th.Tensor
    ) -> tuple[th.Tensor, th.Tensor]:
        """(S, B, A) online values at s, with gradient, and (S, B) the bootstrap value at s'."""
        with th.no_grad():
            next_q_target = self.q_net_target(next_obs)
        eps = exploration_rate.to(next_q_target.dtype).view(-1, 1)
        if self.target == "q":
            return self.q_net(obs), next_q_target.max(dim=2).values
        if self.greedy == "target":
            greedy_value = next_q_target.max(dim=2).values
            return self.q_net(obs), th.lerp(greedy_value, next_q_target.mean(dim=2), eps)
        both = self.q_net(th.cat([obs, next_obs], dim=1))
        batch = obs.shape[1]
        current_q, next_online = both[:, :batch], both[:, batch:].detach()
        ties = (next_online == next_online.max(dim=2, keepdim=True).values).to(next_q_target.dtype)
        greedy = (ties * next_q_target).sum(dim=2) / ties.sum(dim=2)
        return current_q, eps * next_q_target.mean(dim=2) + (1.0 - eps) * greedy

    def _margin_losses(self, states: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """(S,) each member's large-margin loss on its demonstrated minibatch."""
        q = self.q_net(states)
        expert = actions.long().unsqueeze(-1)
        penalty = th.full_like(q, self.demo_margin).scatter(2, expert, 0.0)
        return ((q + penalty).max(dim=2).values - q.gather(2, expert).squeeze(-1)).mean(dim=1)

    def _clip_gradients(self) -> None:
        """Scale each member's gradient to a norm of at most ``max_grad_norm`` (``clip_grad_norm_``'s
        arithmetic, member by member)."""
        grads = [p.grad for p in self.q_net.parameters() if p.grad is not None]
        norms = th.stack([th.linalg.vector_norm(g.flatten(1), dim=1) for g in grads])  # (P, S)
        total = th.linalg.vector_norm(norms, dim=0)
        scale = (self.max_grad_norm / (total + 1e-6)).clamp(max=1.0)
        for g in grads:
            g.mul_(scale.view((-1,) + (1,) * (g.dim() - 1)))


def stack_samples(batches: Sequence[WeightedReplayBufferSamples]) -> WeightedReplayBufferSamples:
    """Each member's batch (every field (B, ...)) stacked to the (S, B, ...) that
    :meth:`StackedExpectedSarsa.train_step` reads."""
    return WeightedReplayBufferSamples(
        *(None if values[0] is None else th.stack(values) for values in zip(*batches, strict=True))
    )
