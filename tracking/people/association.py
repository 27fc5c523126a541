"""Associating detections with tracks: optimal assignment on box overlap (the overlap itself is
:func:`tracking.detection.nms.box_iou`)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def assign(similarity: np.ndarray, threshold: float) -> list[tuple[int, int]]:
    """Pairs ``(row, column)`` of the assignment maximising total similarity, keeping only
    pairs at or above ``threshold`` (Hungarian algorithm, ``scipy.optimize``)."""
    if similarity.size == 0:
        return []
    rows, cols = linear_sum_assignment(-similarity)
    return [
        (int(r), int(c)) for r, c in zip(rows, cols, strict=True) if similarity[r, c] >= threshold
    ]
