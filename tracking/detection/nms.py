"""Greedy non-maximum suppression as voc-release5 ``nms.m``.

Boxes are taken in decreasing score; a box is dropped when a box already kept covers more than
``overlap`` of its own area:

    |B_kept ∩ B_j| / |B_j| > overlap      (voc-release5: overlap 0.5)

This is not the PASCAL intersection-over-union: a small box inside a larger, better one goes even
when their IoU is low (Felzenszwalb et al., PAMI 2010, §7: "we greedily select the highest
scoring ones while skipping detections with bounding boxes that are at least 50% covered by a
bounding box of a previously selected detection"). ``criterion="iou"`` gives the usual
intersection over union instead (OpenCV's ``NMSBoxes``).

Boxes are ``x, y, w, h`` with continuous pixel coordinates, so voc-release5's ``+ 1`` on
inclusive pixel ranges is already in ``w`` and ``h``.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

__all__ = ["NMS_CRITERIA", "NmsCriterion", "box_iou", "check_nms_options", "nms"]

NmsCriterion = Literal["smaller", "iou"]
"""How :func:`nms` measures overlap: over the lower-scoring box's area, or over the union."""
NMS_CRITERIA: tuple[str, ...] = get_args(NmsCriterion)


def check_nms_options(overlap: float, criterion: str, prefix: str = "") -> None:
    """Raise ``ValueError`` unless ``overlap`` is in ``[0, 1]`` and ``criterion`` is one of
    :data:`NMS_CRITERIA`; ``prefix`` names the options as the caller's user spells them
    (``"nms_"`` for the detector configs)."""
    if not 0.0 <= overlap <= 1.0:
        raise ValueError(f"{prefix}overlap must be in [0, 1], got {overlap}")
    if criterion not in NMS_CRITERIA:
        raise ValueError(f"{prefix}criterion must be one of {NMS_CRITERIA}, got {criterion!r}")


def _as_boxes(boxes: object) -> np.ndarray:
    array = np.asarray(boxes, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        raise ValueError(f"boxes must have shape (N, 4), got {array.shape}")
    return array


def box_iou(a: object, b: object) -> np.ndarray:
    """Intersection over union of every box of ``a`` ``(N, 4)`` with every box of ``b`` ``(M, 4)``.

    Returns
    -------
    np.ndarray
        ``(N, M)`` float64; 0 where a box has no area.
    """
    a, b = _as_boxes(a), _as_boxes(b)
    ix = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2]) - np.maximum(
        a[:, None, 0], b[None, :, 0]
    )
    iy = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3]) - np.maximum(
        a[:, None, 1], b[None, :, 1]
    )
    inter = np.clip(ix, 0, None) * np.clip(iy, 0, None)
    union = (a[:, 2] * a[:, 3])[:, None] + (b[:, 2] * b[:, 3])[None, :] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def nms(
    boxes: object,
    scores: object,
    overlap: float = 0.5,
    criterion: NmsCriterion = "smaller",
) -> np.ndarray:
    """Indices of the boxes kept by greedy non-maximum suppression, best score first.

    Parameters
    ----------
    boxes:
        ``(N, 4)`` boxes ``x, y, w, h``.
    scores:
        ``(N,)`` scores; higher is better.
    overlap:
        Suppression threshold in ``[0, 1]`` (voc-release5: 0.5).
    criterion:
        ``"smaller"``: intersection over the area of the lower-scoring box (voc-release5
        ``nms.m``); ``"iou"``: intersection over union.

    Returns
    -------
    np.ndarray
        int64 indices into ``boxes``, in decreasing score.
    """
    boxes = _as_boxes(boxes)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    if scores.shape[0] != boxes.shape[0]:
        raise ValueError(f"scores must have shape ({boxes.shape[0]},), got {scores.shape}")
    check_nms_options(overlap, criterion)
    order = np.argsort(-scores, kind="stable")
    x1, y1 = boxes[order, 0], boxes[order, 1]
    x2, y2 = x1 + boxes[order, 2], y1 + boxes[order, 3]
    area = boxes[order, 2] * boxes[order, 3]
    alive = np.ones(order.size, dtype=bool)
    keep = []
    for i in range(order.size):
        if not alive[i]:
            continue
        keep.append(order[i])
        rest = np.flatnonzero(alive[i + 1 :]) + i + 1
        if rest.size == 0:
            break
        w = np.minimum(x2[i], x2[rest]) - np.maximum(x1[i], x1[rest])
        h = np.minimum(y2[i], y2[rest]) - np.maximum(y1[i], y1[rest])
        inter = np.clip(w, 0, None) * np.clip(h, 0, None)
        # voc-release5: the area of the lower-scoring box; IoU: the union
        denominator = area[rest] if criterion == "smaller" else area[rest] + area[i] - inter
        with np.errstate(invalid="ignore", divide="ignore"):
            covered = np.where(
                denominator > 0, inter / np.where(denominator > 0, denominator, 1), 0
            )
        alive[rest[covered > overlap]] = False
    return np.asarray(keep, dtype=np.int64)
