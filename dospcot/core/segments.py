"""Segment labels: the label budget buys the summed reward of k-step segments of the agents' own
experience (a rater scoring a clip) instead of single rewards (docs/segments.md).

The data flow of a round under segment labels (``training.segment_length`` k > 1):

1. The mask (:class:`~dospcot.envs.RewardMaskWrapper` with ``segment_length`` k) hides every single
   reward and cuts each episode into segments of k steps; a segment is labelled with probability
   ``label_fraction``, and the step that ends it carries the segment's summed reward.
2. :class:`SegmentLabelWrapper` records each finished segment, as the store ids of its steps, into the
   run's :class:`SegmentStore`.
3. A segment is one sample of the co-trainer (the seed paper's k-tuples): its input under view j is
   the sum of its steps' inputs (:func:`segment_pool`), its class a quantile bin of the summed reward.
   Co-training pseudo-labels unlabelled segments as it does single steps.
4. Each view's per-step reward model learns rewards whose segment sums match the labelled sums and the
   admitted pseudo-sums (regression on sums, :func:`fit_step_rewards`); the views' mean per-step
   reward goes into the reward table, weighted by the largest weight of a segment holding the step.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from dospcot.config.learning_sections import ClassifierConfig
from dospcot.core.classifier import BatchedRewardClassifier
from dospcot.core.reward_classes import QuantileRewardClasses
from dospcot.core.self_paced import RunPool
from dospcot.policies.in_place_state import InPlaceState


class SegmentStore(InPlaceState):
    """The segments of one run's experience, each once: a segment is the store ids of its steps.

    A segment seen again (the same steps, as on a deterministic grid) keeps its sample; it is labelled
    once any of its copies is.

    :param length: k, the most steps of a segment (one cut short by an episode's end has fewer).
    """

    def __init__(self, length: int) -> None:
        if length < 2:
            raise ValueError(f"a segment has at least 2 steps, got segment_length {length}")
        self.length = length
        self.ids = np.zeros((0, length), np.int64)
        """(n, k) each segment's store ids, -1 after the last step of a short segment."""
        self.labelled = np.zeros(0, bool)
        self.label = np.zeros(0)
        """(n,) the labelled segments' summed rewards (0 elsewhere)."""
        self.hidden = np.zeros(0)
        """(n,) every segment's true summed reward: metrics only, never the learners."""
        self.rows: dict[tuple[int, ...], int] = {}
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def add(self, ids: Sequence[int], label: float | None, hidden: float) -> int:
        """Record one segment (its steps' store ids), labelled with ``label`` unless it is None;
        return its row."""
        if not 0 < len(ids) <= self.length:
            raise ValueError(f"a segment holds 1 to {self.length} steps, got {len(ids)}")
        key = tuple(int(i) for i in ids)
        n = self.rows.get(key)
        if n is None:
            if self._n == self.labelled.size:
                grow = max(1024, self._n)
                self.ids = np.concatenate([self.ids, np.full((grow, self.length), -1, np.int64)])
                for name in ("labelled", "label", "hidden"):
                    array = getattr(self, name)
                    setattr(self, name, np.concatenate([array, np.zeros(grow, array.dtype)]))
            n = self.rows[key] = self._n
            self.ids[n, : len(key)] = key
            self._n += 1
        if label is not None:
            self.labelled[n], self.label[n] = True, label
        self.hidden[n] = hidden
        return n


class SegmentLabelWrapper(gym.Wrapper):
    """Record every finished segment of an agent's env into a :class:`SegmentStore`.

    Sits above the store wrapper (each step's ``info["store_id"]``), which sits above the mask; it
    sets the mask's ``segment_length`` to the store's k, and reads the mask's ``segment_end`` and
    ``segment_label``. A segment cut off by a reset (the end of a round) is dropped, as the mask drops it.

    :param env: an agent's env, with a :class:`~dospcot.envs.RewardMaskWrapper` in it.
    :param store: the run's segments.
    """

    def __init__(self, env: gym.Env, store: SegmentStore) -> None:
        super().__init__(env)
        env.set_wrapper_attr("segment_length", store.length, force=False)
        self.store = store
        self._ids: list[int] = []
        self._hidden = 0.0

    def reset(self, **kwargs: Any):
        self._ids, self._hidden = [], 0.0
        return self.env.reset(**kwargs)

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._ids.append(int(info["store_id"]))
        self._hidden += float(info["hidden_reward"])
        if info.get("segment_end"):
            self.store.add(self._ids, info.get("segment_label"), self._hidden)
            self._ids, self._hidden = [], 0.0
        return obs, reward, terminated, truncated, info


def segment_pool(steps: RunPool, store: SegmentStore, classes: QuantileRewardClasses) -> RunPool:
    """The co-trainer's pool of segments (one run), after ``classes`` are refitted to every label.

    :param steps: the task's pool of single steps (its features; its labels are empty under segment
        labels), N samples of width d_j per view.
    :param store: the segments, each a row of step ids.
    :param classes: the segment sums' quantile classes.
    :return: n segments, each of width d_j under view j: the sum of its steps' inputs. The label, a
        sum, does not depend on the order of the steps, and neither does the input, which stays as
        wide as a step's.
    """
    n = len(store)
    ids, labelled = store.ids[:n], store.labelled[:n]
    classes.fit(store.label[:n][labelled])
    features = []
    for f in steps.features:
        padded = np.concatenate([f, np.zeros((1, f.shape[1]), f.dtype)])  # row -1: no step
        features.append(padded[ids].sum(axis=1))
    label_class = np.where(labelled, classes.encode(store.label[:n]), -1)
    return RunPool(features, labelled, label_class, ~labelled, classes.mask)


def fit_step_rewards(
    features: np.ndarray,
    ids: np.ndarray,
    sums: np.ndarray,
    weight: np.ndarray,
    config: ClassifierConfig,
    seed: int,
) -> np.ndarray:
    """Per-step rewards whose segment sums match ``sums``: a regression on sums (RRD, Efroni et al.).

    Minimises sum_i w_i (sum_{t in i} r(x_t) - y_i)^2 / sum_i w_i + l2/2 ||theta||^2 / n over a fresh
    model of ``config``'s shape with one output (full-batch Adam, ``config.epochs`` steps).

    :param features: (N, d) every step's input.
    :param ids: (n, k) each segment's step rows, -1 after a short segment's last step.
    :param sums: (n,) each segment's target sum (any value where ``weight`` is 0).
    :param weight: (n,) each segment's weight in [0, 1].
    :param config: the model's shape and optimiser.
    :param seed: its initial parameters.
    :return: (N,) each step's reward.
    """
    model = BatchedRewardClassifier(1, features.shape[1], 1, config, [seed])
    x = torch.from_numpy(np.asarray(features, np.float64))[None]
    keep = weight > 0
    index = torch.from_numpy(np.where(ids[keep] >= 0, ids[keep], features.shape[0]))
    # Sums far apart (a lava step's -100 beside -1 a step) would leave the small rewards to the last
    # digits of the loss: the model fits the sums in units of their spread per step.
    scale = max(float(np.std(sums[keep])) / np.sqrt(ids.shape[1]), 1e-8) if keep.any() else 1.0
    y, w = torch.from_numpy(sums[keep] / scale), torch.from_numpy(weight[keep])
    everything = torch.ones(1, 1, dtype=torch.bool)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.lr)
    for _ in range(config.epochs if keep.any() else 0):
        optimiser.zero_grad()
        step = torch.cat([model(x, everything)[0, :, 0], torch.zeros(1, dtype=x.dtype)])
        residual = step[index].sum(dim=1) - y
        penalty = sum((p**2).sum() for p in model.weights)
        loss = (w * residual**2).sum() / w.sum() + 0.5 * config.l2 * penalty / int(keep.sum())
        loss.backward()
        optimiser.step()
    with torch.no_grad():
        return model(x, everything)[0, :, 0].numpy() * scale


def step_rewards(
    steps: RunPool,
    store: SegmentStore,
    sums: np.ndarray,
    weight: np.ndarray,
    config: ClassifierConfig,
    seeds: Sequence[int],
) -> tuple[np.ndarray, np.ndarray]:
    """Each step's reward for the reward table: the mean over views of :func:`fit_step_rewards`, and
    its weight, the largest weight of a segment holding it (0 for a step in none).

    :param steps: the task's pool of single steps (N samples).
    :param store: the segments.
    :param sums: (n,) each segment's sum: its label, or its admitted pseudo-sum.
    :param weight: (n,) each segment's weight: 1 if labelled, its self-paced weight if admitted, else 0.
    :param config: the per-step models' shape and optimiser.
    :param seeds: one seed per view.
    :return: (N,) rewards and (N,) weights.
    """
    ids = store.ids[: len(store)]
    per_view = [
        fit_step_rewards(f, ids, sums, weight, config, seed)
        for f, seed in zip(steps.features, seeds, strict=True)
    ]
    n_steps = steps.features[0].shape[0]
    step_weight = np.zeros(n_steps + 1)
    np.maximum.at(step_weight, np.where(ids >= 0, ids, n_steps), np.repeat(weight[:, None], ids.shape[1], 1))
    return np.mean(per_view, axis=0), step_weight[:n_steps]


__all__ = ["SegmentLabelWrapper", "SegmentStore", "fit_step_rewards", "segment_pool", "step_rewards"]
