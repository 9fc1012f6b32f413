"""The unlabelled pool of a discrete task, deduplicated by (state, action) key.

Each key is one sample of the pool; its classifier input under a view is the view of s, the one-hot
action and the view of the stored s' (zeros while the key is unseen).
"""

from __future__ import annotations

import numpy as np


def key_features(
    state_features: np.ndarray, next_state: np.ndarray, visited: np.ndarray, n_actions: int
) -> np.ndarray:
    """Classifier inputs of every key, for B runs or for one.

    :param state_features: (S, d) the view of every state.
    :param next_state: (B, S * A) int, the stored s' of each key (any value where unseen); or (S * A,)
        for one run.
    :param visited: (B, S * A) bool, keys the run has seen; or (S * A,).
    :param n_actions: A.
    :return: (B, S * A, 2 d + A) float32; or (S * A, 2 d + A).
    """
    n_states = state_features.shape[0]
    s, a = np.divmod(np.arange(n_states * n_actions), n_actions)
    base = np.concatenate([state_features[s], np.eye(n_actions, dtype=np.float32)[a]], axis=1)
    nxt = state_features[np.where(visited, next_state, 0)] * visited[..., None]
    base = np.broadcast_to(base, (*next_state.shape, base.shape[1]))
    return np.concatenate([base, nxt], axis=-1).astype(np.float32)
