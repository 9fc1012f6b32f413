"""S members' MLP Q-networks as one module: each layer's weights stacked to (S, in, out), applied by one
batched matmul (``torch.baddbmm``) for every member at once.

On a CPU, small networks spend their time in per-call overhead, not arithmetic: one batched call per
layer for S members costs about what one member's ``Linear`` costs, where S networks in a loop cost S
times that. The stacked weights are the transposes of ``nn.Linear``'s (out, in), so that each member's
forward is ``x @ W_s + b_s``.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch as th
from gymnasium import spaces
from stable_baselines3.common.preprocessing import preprocess_obs
from stable_baselines3.dqn.policies import QNetwork
from torch import nn


class StackedQNetwork(nn.Module):
    """S members' ``Flatten -> (Linear -> ReLU) x L -> Linear`` Q-networks (SB3's ``MlpPolicy`` for DQN).

    :param weights: per layer, (S, in, out) float32.
    :param biases: per layer, (S, 1, out) float32.
    :param observation_space: the members' observation space; observations are preprocessed as SB3's
        policies preprocess them (an image space's uint8 pixels cast to float and, under
        ``normalize_images``, divided by 255), so a member computes what its SB3 ``QNetwork`` does.
    :param normalize_images: SB3's flag of the same name.
    """

    def __init__(
        self,
        weights: Sequence[th.Tensor],
        biases: Sequence[th.Tensor],
        observation_space: spaces.Space,
        normalize_images: bool = True,
    ) -> None:
        super().__init__()
        if len(weights) != len(biases) or not weights:
            raise ValueError(f"one bias per weight, at least one layer: got {len(weights)} and {len(biases)}")
        self.observation_space = observation_space
        self.normalize_images = normalize_images
        self.weights = nn.ParameterList(nn.Parameter(w.detach().clone()) for w in weights)
        self.biases = nn.ParameterList(nn.Parameter(b.detach().clone()) for b in biases)

    @classmethod
    def from_q_networks(cls, q_nets: Sequence[QNetwork]) -> StackedQNetwork:
        """The stack of SB3 ``QNetwork``s ``q_nets`` (one per member, the same architecture), their
        weights copied.

        :raises ValueError: a network that is not a flattened MLP with ReLU activations.
        """
        layers = [linear_layers(q_net) for q_net in q_nets]
        shapes = {tuple(tuple(layer.weight.shape) for layer in member) for member in layers}
        if len(shapes) != 1:
            raise ValueError(f"the members' networks differ in shape: {sorted(shapes)}")
        weights = [th.stack([member[i].weight.T for member in layers]) for i in range(len(layers[0]))]
        biases = [th.stack([member[i].bias[None] for member in layers]) for i in range(len(layers[0]))]
        return cls(weights, biases, q_nets[0].observation_space, q_nets[0].normalize_images)

    def forward(self, obs: th.Tensor) -> th.Tensor:
        """(S, B, *obs shape) observations (any dtype the space holds) -> (S, B, A) Q-values."""
        x = preprocess_obs(obs, self.observation_space, self.normalize_images).flatten(2)
        last = len(self.weights) - 1
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = th.baddbmm(bias, x, weight)
            if i < last:
                x = th.relu(x)
        return x

    def member_state_dict(self, member: int) -> dict[str, th.Tensor]:
        """Member ``member``'s weights under the keys of SB3's ``QNetwork`` (``q_net.<i>.weight`` (out,
        in), ``q_net.<i>.bias``), for ``QNetwork.load_state_dict``."""
        state = {}
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            state[f"q_net.{2 * i}.weight"] = weight[member].detach().T.clone()
            state[f"q_net.{2 * i}.bias"] = bias[member, 0].detach().clone()
        return state

    def copy_from(self, other: StackedQNetwork) -> None:
        """Set every member's weights to ``other``'s (a target network's hard update)."""
        with th.no_grad():
            for mine, theirs in zip(self.parameters(), other.parameters(), strict=True):
                mine.copy_(theirs)


def linear_layers(q_net: QNetwork) -> list[nn.Linear]:
    """The ``Linear`` layers of an SB3 ``QNetwork`` whose features are its flattened observation and
    whose hidden activations are ReLU."""
    if type(q_net.features_extractor).__name__ != "FlattenExtractor":
        raise ValueError(
            f"a stacked network flattens its input; got {type(q_net.features_extractor).__name__}"
        )
    modules = list(q_net.q_net)
    if any(type(m).__name__ == "SparseInputLinear" for m in modules):
        raise ValueError(
            "a stacked network has dense layers only; this one has a sparse first layer "
            "(cotraining.numerics = 3 on a view of 0s and 1s): train its seeds one run at a time"
        )
    linear = [m for m in modules if isinstance(m, nn.Linear)]
    others = {type(m).__name__ for m in modules if not isinstance(m, nn.Linear)}
    if others - {"ReLU"}:
        raise ValueError(f"a stacked network has ReLU activations only; got {sorted(others)}")
    return linear
