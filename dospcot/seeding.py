"""Every seed a run derives from its one seed, in one place, one way.

A run takes one integer seed (its config's ``seed``). Each random stream in it (an agent's network
and exploration, the resets of every round, a classifier's initial parameters, the demonstration
episodes) starts from a seed derived here: the first 32-bit word of
``numpy.random.SeedSequence(seed, spawn_key=(stream, *index))``, where ``stream`` names the kind of
stream and ``index`` the agent, round or view. SeedSequence hashes its whole input, so neighbouring
run seeds get unrelated streams, and two streams of one run share a value only if two 32-bit hashes
collide (a chance of about one in four billion per pair). The tests check that no collision occurs
over the seeds the studies use.

Episode seeds are the exception, by design: evaluation episode ``i`` resets with ``EVAL_SEED + i``
in every run, so that every method is scored on the same episodes, and a list of demonstrations
resets with ``demonstration_seed(seed) + i``.
"""

from __future__ import annotations

import numpy as np

EVAL_SEED = 1_000_003
"""Evaluation episode ``i`` resets with seed ``EVAL_SEED + i``, the same in every run."""

# The stream tags: the first word of each derivation's spawn key. Never renumber them: a run's
# seeds, and so its results, depend on them.
(
    _AGENT,
    _ROUND_RESET,
    _CLASSIFIER,
    _LAYER,
    _DEMONSTRATIONS,
    _QUERIES,
    _BATCHED_DRAWS,
    _ENSEMBLE,
    _BOOTSTRAP,
) = range(9)


def _derive(seed: int, stream: int, *index: int) -> int:
    """The seed of stream ``stream`` at ``index`` in run ``seed``: an integer in [0, 2**32)."""
    if seed < 0:
        raise ValueError(f"a seed must be >= 0, got {seed}")
    sequence = np.random.SeedSequence(int(seed), spawn_key=(stream, *map(int, index)))
    return int(sequence.generate_state(1, dtype=np.uint32)[0])


def agent_seed(seed: int, k: int) -> int:
    """Agent ``k``'s seed in run ``seed``: its network (or table), its exploration and (on a task
    whose agents each have their own mask) its env's mask."""
    return _derive(seed, _AGENT, k)


def round_reset_seed(seed: int, k: int, round_: int) -> int:
    """The seed agent ``k``'s env is reset with at the start of round ``round_`` (1-based), so a run
    resumed at a round boundary continues as the uninterrupted run would."""
    return _derive(seed, _ROUND_RESET, k, round_)


def classifier_seed(seed: int, view: int) -> int:
    """The initial parameters of view ``view``'s reward classifier (and, under segment labels, its
    per-step reward model) in run ``seed``."""
    return _derive(seed, _CLASSIFIER, view)


def layer_seed(model_seed: int, fan_in: int, fan_out: int) -> int:
    """The generator seed of one (fan_in, fan_out) layer of a classifier seeded ``model_seed``."""
    return _derive(model_seed, _LAYER, fan_in, fan_out)


def demonstration_seed(seed: int) -> int:
    """The seed of the first demonstration episode a saved agent records for run ``seed``; episode
    ``i`` resets with this seed + ``i``."""
    return _derive(seed, _DEMONSTRATIONS)


def query_seed(seed: int, round_: int) -> int:
    """The seed of the reward queries' random draws in round ``round_`` (1-based) of run ``seed``."""
    return _derive(seed, _QUERIES, round_)


def batched_draws_seed(seed: int, k: int) -> int:
    """The stream agent ``k`` of run ``seed`` draws its exploration, replay batches and demonstration
    minibatches from when the run is a member of a batch (:mod:`dospcot.core.batched_runs`); a run of
    its own draws them from numpy's global generator, which SB3 seeds."""
    return _derive(seed, _BATCHED_DRAWS, k)


def ensemble_seed(seed: int, view: int, member: int) -> int:
    """The initial parameters of member ``member`` of view ``view``'s ensemble of reward classifiers in
    run ``seed`` (the reward-model peer, :mod:`dospcot.core.reward_model`)."""
    return _derive(seed, _ENSEMBLE, view, member)


def bootstrap_seed(seed: int, round_: int) -> int:
    """The seed of the reward-model peer's bootstrap draws of the labels in round ``round_`` (1-based)
    of run ``seed``."""
    return _derive(seed, _BOOTSTRAP, round_)
