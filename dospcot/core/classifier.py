"""Reward classifiers g_j: torch models from (view features of s, action, view features of s') to K
reward classes.

Every classifier here is a *batch* of ``n_models`` independent models with stacked parameters, so
that the vectorised tabular path fits one model per run in one call; the neural path uses
``n_models = 1``. Models never share a parameter, a gradient or a random draw, so a run's model is
the same whatever else is in the batch.

- ``model="mlp"`` with ``loss="cross_entropy"``: a two-layer perceptron.
- ``model="linear"`` with ``loss="hinge"``: a linear multi-class SVM (Weston-Watkins hinge) with the
  L2 penalty 1/2 ||theta||^2, the seed paper's Eq. 8 exactly.

Runs may hold different numbers of classes: ``class_mask`` (n_models, K) marks the classes a run
has seen in its labels; the others get no score and can never be predicted.
"""

from __future__ import annotations

from dataclasses import asdict
from itertools import pairwise
from pathlib import Path

import torch
from torch import nn

from dospcot.config.learning_sections import ClassifierConfig
from dospcot.seeding import layer_seed

_MASKED = -1e9


class BatchedRewardClassifier(nn.Module):
    """``n_models`` independent classifiers over inputs of ``n_features`` and ``n_classes`` outputs.

    :param n_models: number of independent models (runs) in the batch.
    :param n_features: input width.
    :param n_classes: maximum number of reward classes K.
    :param config: hyperparameters.
    :param seeds: one seed per model for its initial parameters.
    :param sparse_inputs: the first layer multiplies only the inputs that are nonzero in some sample
        (the same sums, in another order: for views of 0s and 1s, most of whose inputs are 0 in every
        sample); its weight's gradient stays dense.
    :param fused_adam: :meth:`fit` steps Adam in one fused kernel (the same update, up to rounding).
    """

    sparse_inputs = False
    fused_adam = False

    def __init__(
        self,
        n_models: int,
        n_features: int,
        n_classes: int,
        config: ClassifierConfig,
        seeds: list[int],
        sparse_inputs: bool = False,
        fused_adam: bool = False,
    ) -> None:
        super().__init__()
        self.sparse_inputs, self.fused_adam = sparse_inputs, fused_adam
        if len(seeds) != n_models:
            raise ValueError(f"need one seed per model: {n_models} models, {len(seeds)} seeds")
        self.config = config
        widths = [n_features, config.hidden, n_classes] if config.model == "mlp" else [n_features, n_classes]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in pairwise(widths):
            bound = 1.0 / fan_in**0.5
            w, b = [], []
            for seed in seeds:
                gen = torch.Generator().manual_seed(layer_seed(seed, fan_in, fan_out))
                w.append((torch.rand(fan_in, fan_out, generator=gen, dtype=torch.float64) * 2 - 1) * bound)
                b.append((torch.rand(fan_out, generator=gen, dtype=torch.float64) * 2 - 1) * bound)
            self.weights.append(nn.Parameter(torch.stack(w)))
            self.biases.append(nn.Parameter(torch.stack(b)[:, None, :]))

    def forward(self, x: torch.Tensor, class_mask: torch.Tensor) -> torch.Tensor:
        """Outputs (logits or decision values) of shape (n_models, N, K); absent classes get -1e9.

        :param x: inputs of shape (n_models, N, n_features).
        :param class_mask: bool (n_models, K), the classes each model may predict, or (n_models, N, K),
            those each sample may take.
        """
        cols = self._nonzero_inputs(x)
        return self._outputs(x if cols is None else x.index_select(2, cols), class_mask, cols)

    def _nonzero_inputs(self, x: torch.Tensor) -> torch.Tensor | None:
        """(n,) the inputs nonzero in some sample of ``x`` (n_models, N, n_features), under
        ``sparse_inputs``; None: every input."""
        if not self.sparse_inputs or x.requires_grad:
            return None
        return x.abs().amax(dim=(0, 1)).nonzero().view(-1)

    def _outputs(self, x: torch.Tensor, class_mask: torch.Tensor, cols: torch.Tensor | None) -> torch.Tensor:
        """:meth:`forward` of ``x`` (n_models, N, n) holding only the inputs ``cols`` (None: all): the
        first layer reads their weight rows alone (the others would multiply inputs that are 0)."""
        h = x
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = torch.baddbmm(b, h, w if i > 0 or cols is None else w.index_select(1, cols))
            if i < len(self.weights) - 1:
                h = torch.relu(h)
        return h.masked_fill(~_per_sample(class_mask), _MASKED)

    def class_losses(self, outputs: torch.Tensor, class_mask: torch.Tensor) -> torch.Tensor:
        """Loss L(y, g(x)) for every candidate label y: shape (n_models, N, K); +inf for absent classes."""
        if self.config.loss == "cross_entropy":
            losses = -torch.log_softmax(outputs, dim=-1)
        else:
            # Weston-Watkins: L(y) = sum over present c != y of max(0, 1 - f_y + f_c).
            margins = torch.relu(1.0 - outputs[..., :, None] + outputs[..., None, :])
            present = _per_sample(class_mask)[:, :, None, :].to(outputs.dtype)
            losses = (margins * present).sum(-1) - 1.0  # drops the c == y term, which is exactly 1
        return losses.masked_fill(~_per_sample(class_mask), float("inf"))

    def scores(self, x: torch.Tensor, class_mask: torch.Tensor) -> torch.Tensor:
        """Confidence of every class in [0, 1]: softmax of the outputs; shape (n_models, N, K)."""
        with torch.no_grad():
            return torch.softmax(self(x, class_mask), dim=-1)

    def fit(
        self, x: torch.Tensor, y: torch.Tensor, weight: torch.Tensor, class_mask: torch.Tensor
    ) -> torch.Tensor:
        """Minimise sum_i w_i L(y_i, g(x_i)) / sum_i w_i + l2/2 ||theta||^2 / n, per model.

        Eq. 8 of the paper with labels weighted 1 and pseudo-labels by their self-paced weight.

        :param x: (n_models, N, n_features).
        :param y: int (n_models, N), class index of each sample (any value where ``weight`` is 0).
        :param weight: (n_models, N) sample weights in [0, 1].
        :param class_mask: bool (n_models, K) or (n_models, N, K), as in :meth:`forward`.
        :return: the final weighted loss of each model, shape (n_models,).
        """
        optimiser = torch.optim.Adam(self.parameters(), lr=self.config.lr, fused=self.fused_adam or None)
        y = y.clamp(min=0)[..., None]
        total = weight.sum(-1).clamp(min=1e-12)
        n = (weight > 0).sum(-1).clamp(min=1)
        cols = self._nonzero_inputs(x)
        if cols is not None:  # once for every epoch
            x = x.index_select(2, cols)
        for _ in range(self.config.epochs):
            optimiser.zero_grad()
            outputs = self._outputs(x, class_mask, cols)
            per_sample = self.class_losses(outputs, class_mask).gather(-1, y)[..., 0]
            data = (torch.where(weight > 0, per_sample, 0.0) * weight).sum(-1) / total
            penalty = sum((w**2).sum(dim=(1, 2)) for w in self.weights)
            loss = data + 0.5 * self.config.l2 * penalty / n
            # Summing keeps each model's gradient its own: d(sum)/d(loss_b) = 1.
            loss.sum().backward()
            optimiser.step()
        return loss.detach()


def _per_sample(class_mask: torch.Tensor) -> torch.Tensor:
    """A class mask as (n_models, N or 1, K): one per model broadcasts over its samples."""
    return class_mask[:, None, :] if class_mask.dim() == 2 else class_mask


def save_classifier(clf: BatchedRewardClassifier, path: str | Path) -> None:
    """Save a classifier's shape, config and parameters with ``torch.save`` (no pickled classes)."""
    first = clf.weights[0]
    torch.save(
        {
            "n_models": int(first.shape[0]),
            "n_features": int(first.shape[1]),
            "n_classes": int(clf.weights[-1].shape[2]),
            "config": asdict(clf.config),
            "state_dict": clf.state_dict(),
        },
        path,
    )


def load_classifier(path: str | Path) -> BatchedRewardClassifier:
    """Load what :func:`save_classifier` wrote, with ``weights_only=True`` (no code runs on load).

    :raises ValueError: the file is missing, truncated, corrupt or not a classifier.
    """
    try:
        data = torch.load(path, weights_only=True)
        clf = BatchedRewardClassifier(
            data["n_models"],
            data["n_features"],
            data["n_classes"],
            ClassifierConfig(**data["config"]),
            seeds=[0] * data["n_models"],
        )
        clf.load_state_dict(data["state_dict"])
    except Exception as err:  # torch, zipfile and pickle raise many types for a damaged file
        reason = f"{type(err).__name__}: {err}"
        raise ValueError(f"{path} is not a readable dospcot classifier ({reason})") from None
    return clf
