"""Associating detections with tracks: optimal assignment on a similarity matrix."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def assign(similarity: np.ndarray, threshold: float = -np.inf) -> list[tuple[int, int]]:
    """Pairs ``(row, column)`` of the assignment maximising total similarity among the pairs
    whose similarity is finite and at or above ``threshold`` (Hungarian algorithm,
    ``scipy.optimize``); ``-inf`` marks a pair that may not match."""
    allowed = np.isfinite(similarity) & (similarity >= threshold)
    if not allowed.any():
        return []
    # A forbidden pair costs more than any allowed assignment gains, so it is chosen only
    # where nothing else is left, and then dropped below.
    finite = similarity[allowed]
    forbidden = finite.min() - 1.0 - (finite.max() - finite.min()) * min(similarity.shape)
    rows, cols = linear_sum_assignment(-np.where(allowed, similarity, forbidden))
    return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if allowed[r, c]]
