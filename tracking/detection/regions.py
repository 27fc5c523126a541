"""Validation and clipping of regions of interest, height ranges and boxes (shared by the
detectors)."""

from __future__ import annotations

import math

import numpy as np

from tracking.types import Box, as_box

__all__ = ["centres_inside", "checked_heights", "checked_region", "clip_boxes", "clip_region"]


def checked_region(region: object) -> Box:
    """``region`` (a :class:`Box` or four numbers ``(x, y, w, h)``, as trackers take boxes)
    as a Box with finite coordinates and a positive size.

    Raises
    ------
    TypeError
        If ``region`` is neither.
    ValueError
        If a coordinate is not finite or the size is not positive.
    """
    region = as_box(region)
    if not all(math.isfinite(v) for v in (region.x, region.y, region.w, region.h)):
        raise ValueError(f"region must have finite coordinates, got {region}")
    if region.w <= 0 or region.h <= 0:
        raise ValueError(f"region must have a positive size, got {region.w}x{region.h}")
    return region


def clip_region(region: Box, shape: tuple[int, ...]) -> Box | None:
    """``region`` clipped to a frame of ``shape`` ``(H, W, ...)``; ``None`` if nothing is left."""
    x1, y1 = max(region.x, 0.0), max(region.y, 0.0)
    x2 = min(region.x + region.w, float(shape[1]))
    y2 = min(region.y + region.h, float(shape[0]))
    if x2 <= x1 or y2 <= y1:
        return None
    return Box(x1, y1, x2 - x1, y2 - y1)


def checked_heights(heights: object) -> tuple[float, float]:
    """``(min, max)`` person heights in pixels with ``0 < min <= max``, or ValueError."""
    try:
        # not iterable, or not two numbers: the TypeError or ValueError below
        low, high = (float(h) for h in heights)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as error:
        raise ValueError(f"heights must be (min, max) in pixels, got {heights!r}") from error
    if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
        raise ValueError(f"heights must satisfy 0 < min <= max, got {heights!r}")
    return low, high


def clip_boxes(boxes: np.ndarray, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Boxes ``(N, 4)`` clipped to an image of ``shape``, those left empty dropped; the boxes
    and the rows kept (voc-release5 ``clipboxes.m``; OpenCV's ``detectMultiScale`` clips alike)."""
    height, width = shape[:2]
    x1 = np.maximum(boxes[:, 0], 0.0)
    y1 = np.maximum(boxes[:, 1], 0.0)
    x2 = np.minimum(boxes[:, 0] + boxes[:, 2], width)
    y2 = np.minimum(boxes[:, 1] + boxes[:, 3], height)
    keep = np.flatnonzero((x2 > x1) & (y2 > y1))
    return np.column_stack([x1, y1, x2 - x1, y2 - y1])[keep], keep


def centres_inside(boxes: np.ndarray, region: Box) -> np.ndarray:
    """Whether the centre of each box ``(N, 4)`` lies in ``region`` (edges included): which
    detections a region search reports."""
    cx, cy = boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3] / 2
    return (
        (cx >= region.x)
        & (cx <= region.x + region.w)
        & (cy >= region.y)
        & (cy <= region.y + region.h)
    )
