"""Associating detections with tracks: optimal assignment on box overlap."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union of every box of ``a`` ``(A, 4)`` with every box of ``b``
    ``(B, 4)`` (x, y, w, h): ``(A, B)``."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    x1 = np.maximum(a[:, None, 0], b[None, :, 0])
    y1 = np.maximum(a[:, None, 1], b[None, :, 1])
    x2 = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2])
    y2 = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    union = (a[:, None, 2] * a[:, None, 3]) + (b[None, :, 2] * b[None, :, 3]) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def assign(similarity: np.ndarray, threshold: float) -> list[tuple[int, int]]:
    """Pairs ``(row, column)`` of the assignment maximising total similarity, keeping only
    pairs at or above ``threshold`` (Hungarian algorithm, ``scipy.optimize``)."""
    if similarity.size == 0:
        return []
    rows, cols = linear_sum_assignment(-similarity)
    return [
        (int(r), int(c)) for r, c in zip(rows, cols, strict=True) if similarity[r, c] >= threshold
    ]
