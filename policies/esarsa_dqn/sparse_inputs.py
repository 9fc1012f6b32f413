"""A first layer for views of 0s and 1s: the sum of the weight rows of the inputs that are on.

A one-hot or indicator view (MiniGrid's egocentric map: 2,535 inputs, at most 338 of them on in a
sample, about 410 in any sample of a batch of 64 on LavaGapS7) makes a dense first layer multiply
every weight by an input that is mostly 0. :class:`SparseInputLinear` computes the same
``x @ W.T + b`` over the inputs that are on in some sample of the batch: one matrix product of the
batch's nonzero columns with the weight rows they select. It is exact for any values (an input left
out is 0 in every sample). Its weight's gradient is dense, of the weight's shape (zero on the rows
no input in the batch turned on), so Adam sees what it sees under ``nn.Linear``.

The weight is held as ``W.T``, (in, out), contiguous: the rows the product reads are contiguous, the
gradient is written in that layout, and a fused optimiser reads both without a copy. Its state
dict holds ``weight`` (out, in) and ``bias`` (out,), as ``nn.Linear``'s does, so a network saved
with it loads into the stock network and back.
"""

from __future__ import annotations

from typing import Any

import torch as th
import torch.nn.functional as F
from torch import nn


class SparseInputLinear(nn.Module):
    """``nn.Linear``'s ``x @ W.T + b`` over the inputs that are nonzero in some sample of the batch (see
    the module docstring). Inputs that require a gradient take the dense product (they get their
    gradient).

    :param linear: the layer whose parameters this one starts from (copied; ``linear`` is left as it
        is). Its bias, if any, is the same ``Parameter`` object.
    """

    def __init__(self, linear: nn.Linear) -> None:
        super().__init__()
        self.in_features, self.out_features = linear.in_features, linear.out_features
        self.weight_t = nn.Parameter(linear.weight.detach().t().contiguous())
        """(in_features, out_features): ``nn.Linear``'s weight, transposed."""
        self.bias = linear.bias

    @property
    def weight(self) -> th.Tensor:
        """(out_features, in_features): the weight as ``nn.Linear`` holds it (a view)."""
        return self.weight_t.t()

    def forward(self, x: th.Tensor) -> th.Tensor:
        """:param x: (batch, in_features). :return: (batch, out_features)."""
        if x.dim() != 2 or x.requires_grad:
            return F.linear(x, self.weight, self.bias)
        # The inputs on in any sample of the batch: in a view of indicators most inputs are 0 in every
        # sample (cells off the map, object types the task lacks), and the rows they select make one
        # product as fast as a dense one per input. A zero input adds exactly 0 to the sum it leaves.
        cols = x.abs().amax(0).nonzero().view(-1)
        h = x.index_select(1, cols) @ self.weight_t.index_select(0, cols)
        return h if self.bias is None else h + self.bias

    def extra_repr(self) -> str:
        bias = self.bias is not None
        return f"in_features={self.in_features}, out_features={self.out_features}, bias={bias}"

    def _save_to_state_dict(self, destination: dict[str, Any], prefix: str, keep_vars: bool) -> None:
        # nn.Linear's keys and shapes: the stock network loads what this one saves.
        weight = self.weight_t if keep_vars else self.weight_t.detach()
        destination[prefix + "weight"] = weight.t()
        if self.bias is not None:
            destination[prefix + "bias"] = self.bias if keep_vars else self.bias.detach()

    def _load_from_state_dict(
        self,
        state_dict: dict[str, Any],
        prefix: str,
        local_metadata: dict[str, Any],
        strict: bool,
        missing_keys: list[str],
        unexpected_keys: list[str],
        error_msgs: list[str],
    ) -> None:
        expected = {"weight": (self.out_features, self.in_features), "bias": (self.out_features,)}
        targets = {"weight": self.weight_t, "bias": self.bias}
        for name, shape in expected.items():
            param, key = targets[name], prefix + name
            if param is None:
                continue
            if key not in state_dict:
                missing_keys.append(key)
                continue
            value = state_dict[key]
            if tuple(value.shape) != shape:
                error_msgs.append(f"size mismatch for {key}: copying {tuple(value.shape)}, expected {shape}")
                continue
            with th.no_grad():
                param.copy_(value.t() if name == "weight" else value)


def sparsify_first_layer(network: nn.Module) -> SparseInputLinear | None:
    """Replace the first ``nn.Linear`` among ``network``'s modules by a :class:`SparseInputLinear`
    with its parameters (the bias stays the same object); return it, or None if there is none."""
    for module in network.modules():
        for name, child in module.named_children():
            if type(child) is nn.Linear:
                sparse = SparseInputLinear(child)
                setattr(module, name, sparse)
                return sparse
    return None


def stock_optimizer_state(optimizer: th.optim.Optimizer, params: list[nn.Parameter]) -> dict[str, Any]:
    """``optimizer.state_dict()`` with the 2-d state tensors (Adam's moments) of ``params``, each a
    :class:`SparseInputLinear`'s ``weight_t``, transposed into ``nn.Linear``'s layout: the state a
    stock network's optimiser loads. The optimiser itself is left as it is."""
    state_dict = optimizer.state_dict()
    ordered = [p for group in optimizer.param_groups for p in group["params"]]
    for index in (i for i, p in enumerate(ordered) if any(p is q for q in params)):
        state = state_dict["state"].get(index)
        if state is not None:
            state_dict["state"][index] = {
                k: v.t() if isinstance(v, th.Tensor) and v.dim() == 2 else v for k, v in state.items()
            }
    return state_dict


def own_optimizer_state(optimizer: th.optim.Optimizer, params: list[nn.Parameter]) -> None:
    """The inverse of :func:`stock_optimizer_state`, in place: after ``optimizer`` loaded state saved
    in ``nn.Linear``'s layout, transpose the 2-d state tensors of ``params`` into theirs."""
    for param in params:
        state = optimizer.state.get(param, {})
        for name, value in state.items():
            if isinstance(value, th.Tensor) and value.dim() == 2:
                state[name] = value.t().contiguous()
