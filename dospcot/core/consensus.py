"""The consensus pseudo-reward of the seed paper's Eq. 9.

``y_k = argmin_y sum_j v_jk * L(y, g_j(phi_jk))``: with cross-entropy, the class maximising
``sum_j v_jk log p_j(y | phi_jk)``. A sample whose weights are all zero stays unlabelled (-1).
"""

from __future__ import annotations

import numpy as np


def consensus_labels(class_losses: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Eq. 9 over m views.

    :param class_losses: (m, B, N, K) loss of each candidate class under each view; +inf marks a
        class the run has never seen.
    :param weights: (m, B, N) self-paced weights v_j.
    :return: (B, N) int class index, -1 where every weight is 0.
    """
    w = np.broadcast_to(weights[..., None], class_losses.shape)
    # Zero-weight views contribute nothing, even where their loss is +inf (a class they never saw).
    contributions = np.multiply(w, class_losses, out=np.zeros(class_losses.shape), where=w > 0)
    weighted = contributions.sum(axis=0)
    labels = weighted.argmin(axis=-1)
    return np.where(weights.sum(axis=0) > 0, labels, -1)
