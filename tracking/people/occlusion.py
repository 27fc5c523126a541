"""Occlusion reasoning (DESIGN.md §5): the person whose box ends lower in the image is nearer
the camera and covers the other."""

from __future__ import annotations

import numpy as np


def occluders(boxes: np.ndarray, min_overlap: float) -> np.ndarray:
    """Which boxes cover which: ``(T, T)`` bool, ``[i, j]`` when ``j`` is nearer than ``i``
    (its bottom edge is lower) and covers at least ``min_overlap`` of ``i``'s area."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    x1 = np.maximum(boxes[:, None, 0], boxes[None, :, 0])
    y1 = np.maximum(boxes[:, None, 1], boxes[None, :, 1])
    x2 = np.minimum(boxes[:, None, 0] + boxes[:, None, 2], boxes[None, :, 0] + boxes[None, :, 2])
    y2 = np.minimum(boxes[:, None, 1] + boxes[:, None, 3], boxes[None, :, 1] + boxes[None, :, 3])
    inter = np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)
    area = boxes[:, 2] * boxes[:, 3]
    bottom = boxes[:, 1] + boxes[:, 3]
    nearer = bottom[None, :] > bottom[:, None]
    covered = inter >= min_overlap * np.maximum(area[:, None], 1e-9)
    out = nearer & covered
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
