"""Every seed a run derives from its one seed, in one place.

A run takes one integer seed (its config's ``seed``). Each random stream in it (an agent's network
and exploration, the resets of every round, a classifier's initial parameters, the evaluation and
demonstration episodes) starts from a seed derived here. Within one stream no seed repeats (one per
agent, round or view); streams that feed different generators may share a value (seed 0's first
agent and first classifier both get 0), which is harmless since they never draw from each other.

The tabular agents' seeds come from :class:`numpy.random.SeedSequence`. The other derivations are
the integer arithmetic the committed study records were produced with; moving them to
``SeedSequence`` changes every neural result, so it waits for a rerun of every record
(docs/design.md, "Seeds").
"""

from __future__ import annotations

import numpy as np

EVAL_SEED = 1_000_003
"""Evaluation episodes start from seeds ``EVAL_SEED + i``, apart from every training seed."""
DEMO_SEED = 3_000_017
"""A saved agent's demonstrations of run seed s start from seeds ``DEMO_SEED + 10,000 s + i``, apart
from the evaluation episodes."""


def agent_seed(seed: int, k: int) -> int:
    """Agent ``k``'s seed in run ``seed``: its network, its exploration and (on a task whose agents
    each have their own mask) its env's mask. Distinct for k < 1000."""
    return seed * 1000 + k


def round_reset_seed(seed: int, k: int, round_: int) -> int:
    """The seed agent ``k``'s env is reset with at the start of round ``round_`` (1-based), so a run
    resumed at a round boundary continues as the uninterrupted run would."""
    return agent_seed(seed, k) + 7919 * round_


def classifier_seed(seed: int, view: int) -> int:
    """The initial parameters of view ``view``'s reward classifier (and, under segment labels, its
    per-step reward model) in run ``seed``."""
    return seed * 101 + view


def layer_seed(model_seed: int, fan_in: int, fan_out: int) -> int:
    """The generator seed of one (fan_in, fan_out) layer of a classifier seeded ``model_seed``."""
    return int(model_seed) * 7919 + fan_in * 31 + fan_out


def tabular_agent_seed(seed: int, k: int) -> int:
    """Agent ``k``'s seed in a tabular (paper-protocol) run ``seed``."""
    return int(np.random.SeedSequence([seed, k]).generate_state(1)[0])


def demonstration_seed(seed: int) -> int:
    """The seed of the first demonstration episode a saved agent records for run ``seed``."""
    return DEMO_SEED + 10_000 * seed
