"""Episode-end queries spread over the distinct states the ends reached
(``training.query_end_states = "spread"``, the ``"outcomes"`` strategy's episode ends;
docs/queries.md): a sparse task's rare goal is one distinct end state among few, so it is asked about
early where a draw among the many ends alike would wait for it."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

EndStates = Callable[[np.ndarray], np.ndarray]
"""Describes the states that samples ``ids`` led to (their s'): (len(ids),) int keys on a pool whose
states have keys, else (len(ids), d) float features (every view of s', flattened)."""


def spread_ends(
    ends: np.ndarray,
    n: int,
    end_states: EndStates,
    labelled_ends: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """``n`` of the episode ends ``ends`` (sample ids), spread over the distinct states they reached.

    Where ends are many and alike (a sparse task's failures), a rare end (its goal) is one distinct
    state among few, so covering the distinct states asks about it early, where a draw at random among
    the ends would wait for it in proportion to how rare it is.

    Each pick takes a sample of the end state asked about least so far, counting the labelled ends
    ``labelled_ends`` (earlier rounds' answers, the mask's, demonstrations') as asked: no state is
    asked twice before every state was asked once, and one no label has shown comes first. Ties go to
    the state farthest from every state asked (features only: a k-center / farthest-point traversal),
    then to the state with the fewest candidate ends (the rarer outcome), then at random.

    States are told apart by their key where ``end_states`` gives keys. From features, two ends share a
    state when their features agree to 6 decimals (float noise of a stored view is not a new state);
    distances are Euclidean over the features scaled to unit spread (a constant feature to 1), so no
    view's units outweigh another's; with no labelled end, the first pick is the state farthest from
    the ends' mean, the most unusual end. Farthest-point is deterministic given its start and costs
    O(n x states x d), which a round's few hundred ends make cheap, where a clustering (k-means) would
    need restarts and a chosen k.

    :param ends: (E,) int, the candidate samples that ended their episode.
    :param n: how many to choose (at most E).
    :param end_states: describes each sample's end state (:data:`EndStates`).
    :param labelled_ends: (L,) int, the labelled samples that ended their episode.
    :param rng: the round's query stream: the order within a state, and the last tie-break.
    :return: (min(n, E),) int sample ids in the order chosen.
    """
    n = min(n, ends.size)
    if n <= 0:
        return np.zeros(0, dtype=np.int64)
    ends = np.sort(ends)  # the choice depends on the seed, not on the order the ends came in
    described = np.asarray(end_states(np.concatenate([ends, labelled_ends]).astype(np.int64)))
    keyed = described.ndim == 1
    if keyed:
        _, group = np.unique(described, return_inverse=True)
    else:
        # + 0.0 turns -0.0 into 0.0, so that rounding never splits one state in two.
        described = np.round(described.reshape(described.shape[0], -1).astype(np.float64), 6) + 0.0
        _, first, group = np.unique(described, axis=0, return_index=True, return_inverse=True)
    group = group.reshape(-1)
    states = int(group.max()) + 1
    candidate_state, labelled_state = group[: ends.size], group[ends.size :]
    size = np.bincount(candidate_state, minlength=states)
    asked = np.bincount(labelled_state, minlength=states)
    # Squared distances: the same order as distances, and each update one matrix-vector product.
    distance = np.zeros(states)
    if not keyed:
        spread = described.std(axis=0)
        scaled = described / np.where(spread > 0, spread, 1.0)
        points = scaled[first]  # one point per state, in state order
        norms = np.einsum("ij,ij->i", points, points)

        def squared_from(state: int) -> np.ndarray:
            return np.maximum(norms + norms[state] - 2.0 * (points @ points[state]), 0.0)

        if labelled_ends.size:
            distance = np.full(states, np.inf)
            for seen in np.unique(labelled_state):
                distance = np.minimum(distance, squared_from(int(seen)))
        else:
            distance = ((points - scaled[: ends.size].mean(axis=0)) ** 2).sum(axis=1)
    rank = rng.permutation(states)
    # Each state's candidates in a random order: a state asked again gives its next one.
    order = rng.permutation(ends.size)
    order = order[np.argsort(candidate_state[order], kind="stable")]
    start = np.concatenate([[0], np.cumsum(size)[:-1]])
    taken = np.zeros(states, dtype=np.int64)
    chosen: list[int] = []
    for _ in range(n):
        open_ = np.flatnonzero(taken < size)
        # Rounded, so that float noise never breaks a tie between equally far states (equidistant
        # one-hot cells): those go to the fewest candidates.
        far = np.round(distance[open_], 6)
        # lexsort sorts by its last key first: least asked, farthest, fewest candidates, at random.
        best = open_[np.lexsort((rank[open_], size[open_], -far, asked[open_]))[0]]
        chosen.append(int(ends[order[start[best] + taken[best]]]))
        taken[best] += 1
        asked[best] += 1
        if not keyed and distance[open_].max() > 0:  # once every state was asked, all are 0
            distance = np.minimum(distance, squared_from(int(best)))
    return np.asarray(chosen, dtype=np.int64)
