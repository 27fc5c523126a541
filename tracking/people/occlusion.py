"""Occlusion reasoning (docs/architecture.md §5): the person whose box ends lower in the image is
nearer the camera and covers the other."""

from __future__ import annotations

import numpy as np


def covered_share(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(A, B)``: the share of each box of ``a`` (x, y, w, h) that each box of ``b`` covers."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    x1 = np.maximum(a[:, None, 0], b[None, :, 0])
    y1 = np.maximum(a[:, None, 1], b[None, :, 1])
    x2 = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2])
    y2 = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    return inter / np.maximum(a[:, 2] * a[:, 3], 1e-9)[:, None]


def occluders(boxes: np.ndarray, min_overlap: float) -> np.ndarray:
    """Which boxes cover which: ``(T, T)`` bool, ``[i, j]`` when ``j`` is nearer than ``i``
    (its bottom edge is lower) and covers at least ``min_overlap`` of ``i``'s area."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    bottom = boxes[:, 1] + boxes[:, 3]
    nearer = bottom[None, :] > bottom[:, None]
    out = nearer & (covered_share(boxes, boxes) >= min_overlap)
    np.fill_diagonal(out, False)
    return out


def hidden_points(points: np.ndarray, cover: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Which points of each person lie inside a box that covers that person.

    Parameters
    ----------
    points:
        ``(T, P, 2)`` part positions (x, y).
    cover:
        ``(T, T)`` from :func:`occluders`.
    boxes:
        ``(T, 4)``.

    Returns
    -------
    ndarray, bool, ``(T, P)``
    """
    x, y = points[..., 0][:, :, None], points[..., 1][:, :, None]  # (T, P, 1)
    bx, by = boxes[None, None, :, 0], boxes[None, None, :, 1]
    inside = (x >= bx) & (x <= bx + boxes[None, None, :, 2])
    inside &= (y >= by) & (y <= by + boxes[None, None, :, 3])  # (T, P, T)
    return np.any(inside & cover[:, None, :], axis=-1)
