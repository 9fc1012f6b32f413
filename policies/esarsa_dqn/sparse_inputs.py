"""A first layer for views of 0s and 1s: the sum of the weight rows of the inputs that are on.

A one-hot or indicator view (MiniGrid's egocentric map: 2,535 inputs, at most 338 of them on) makes
a dense first layer multiply every weight by an input that is mostly 0. :class:`SparseInputLinear`
computes the same ``x @ W.T + b`` from the nonzero inputs alone: ``F.embedding_bag`` sums the rows
of ``W.T`` they select, each scaled by its input, so it is exact for any values, and fast where few
are nonzero. Its weight's gradient is dense, of the weight's shape (zero on the rows no input in the
batch turned on), so Adam sees what it sees under ``nn.Linear``.

The weight is held as ``W.T``, (in, out), contiguous: the rows the sum reads are contiguous, the
gradient is written in that layout, and a fused optimiser reads both without a copy. Its state
dict holds ``weight`` (out, in) and ``bias`` (out,), as ``nn.Linear``'s does, so a network saved
with it loads into the stock network and back.
"""

from __future__ import annotations

from typing import Any

import torch as th
import torch.nn.functional as F
from torch import nn


class _RowSum(th.autograd.Function):
    """``h[b] = sum_k values[k] * weight_t[cols[k]]`` over the entries ``k`` of row ``b``, with the
    dense gradient of ``weight_t`` (no gradient for the inputs)."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any, weight_t: th.Tensor, rows: th.Tensor, cols: th.Tensor, values: th.Tensor, n: int
    ) -> th.Tensor:
        """:param weight_t: (in, out); ``rows``, ``cols``: (nnz,) int64, the nonzero inputs' batch
        rows (sorted) and input indices; ``values``: (nnz,) their values; ``n``: the batch size.
        :return: (n, out)."""
        counts = th.bincount(rows, minlength=n)
        offsets = counts.cumsum(0) - counts
        ctx.save_for_backward(rows, cols, values)
        ctx.weight_shape = weight_t.shape
        return F.embedding_bag(cols, weight_t, offsets, mode="sum", per_sample_weights=values)

    @staticmethod
    def backward(ctx: Any, grad: th.Tensor) -> tuple[th.Tensor | None, ...]:  # type: ignore[override]
        rows, cols, values = ctx.saved_tensors
        # index_add rather than embedding_bag's own backward, which sorts the indices first.
        contributions = grad.index_select(0, rows) * values[:, None]
        grad_weight = grad.new_zeros(ctx.weight_shape).index_add_(0, cols, contributions)
        return grad_weight, None, None, None, None


class SparseInputLinear(nn.Module):
    """``nn.Linear``'s ``x @ W.T + b`` summed over the nonzero inputs of each sample (see the module
    docstring). Inputs that require a gradient take the dense product (they get their gradient).

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
        rows, cols = x.nonzero(as_tuple=True)
        h = _RowSum.apply(self.weight_t, rows, cols, x[rows, cols].to(self.weight_t.dtype), x.shape[0])
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
