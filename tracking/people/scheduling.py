"""When the tracker runs its own detector: the full frame now and then, regions of interest
around the tracks in between (docs/architecture.md §5, detector scheduling)."""

from __future__ import annotations

import numpy as np

from tracking.detection.base import Detections, Detector
from tracking.detection.nms import nms
from tracking.people.config import PeopleTrackerConfig
from tracking.types import Box


class DetectionScheduler:
    """Decides, frame by frame, where the detector looks.

    The full frame is searched when ``full_detection_interval`` seconds have passed since the
    last full search (every frame when it is 0) or nobody is tracked; otherwise only the
    regions around the predicted boxes (:func:`search_regions`), for people of about the
    predicted heights, which costs a fraction of a full search.

    "Passed" allows a quarter of the time since the previous frame: timestamps such as
    ``index / 25`` miss ``0.2`` by a rounding error (0.6 - 0.4 < 0.2) and camera clocks jitter,
    and without it the search would fall a frame late now and then.
    """

    def __init__(self, detector: Detector, config: PeopleTrackerConfig) -> None:
        self._detector = detector
        self._config = config
        self.reset()

    def reset(self) -> None:
        self._last_full: float | None = None
        self._previous: float | None = None

    def detect(self, frame: np.ndarray, timestamp: float, predicted: np.ndarray) -> Detections:
        c = self._config
        slack = 0.0 if self._previous is None else 0.25 * (timestamp - self._previous)
        self._previous = timestamp
        due = (
            self._last_full is None
            or timestamp - self._last_full >= c.full_detection_interval - slack
        )
        # a source indexed by frame must be read on every frame, or it falls behind the video
        if due or len(predicted) == 0 or getattr(self._detector, "frame_indexed", False):
            self._last_full = timestamp
            return self._detector.detect(frame)
        regions = search_regions(predicted, frame.shape, c.region_margin, c.region_heights)
        # a detector that batches its regions (the CNN: one inference for all) says so
        batched = getattr(self._detector, "detect_regions", None)
        if batched is not None:
            found = batched(frame, regions)
        else:
            found = [self._detector.detect_region(frame, box, h) for box, h in regions]
        return merge(found, self._detector.part_names)


def search_regions(
    predicted: np.ndarray,
    shape: tuple[int, ...],
    margin: float,
    heights: tuple[float, float],
) -> list[tuple[Box, tuple[float, float]]]:
    """Where to look for the people of ``predicted`` boxes ``(N, 4)`` in a frame of ``shape``.

    Each box widened by ``margin`` of its height on every side and clipped to the frame,
    searched for people ``heights[0] .. heights[1]`` times its height. A search costs about
    its area over the square of the smallest height it looks for (the pixels of the finest
    pyramid level it scans), so regions are merged, pair by pair, into the box around them
    while that costs less than searching them apart: the overlapping regions of a group of
    people become one search instead of one per person.
    """
    boxes = np.asarray(predicted, dtype=np.float64).reshape(-1, 4)
    corners, keep = widened(boxes, shape, margin)
    ranges = boxes[:, 3:4] * np.asarray(heights, dtype=np.float64)
    corners, ranges = corners[keep], ranges[keep]
    while len(corners) > 1:
        cost = _area(corners) / ranges[:, 0] ** 2
        union = np.concatenate(
            [
                np.minimum(corners[:, None, :2], corners[None, :, :2]),
                np.maximum(corners[:, None, 2:], corners[None, :, 2:]),
            ],
            axis=2,
        )
        low = np.minimum(ranges[:, None, 0], ranges[None, :, 0])
        saving = cost[:, None] + cost[None, :] - _area(union) / low**2
        np.fill_diagonal(saving, -np.inf)
        i, j = np.unravel_index(np.argmax(saving), saving.shape)
        if saving[i, j] <= 0:
            break
        corners[i] = union[i, j]
        ranges[i] = (low[i, j], max(ranges[i, 1], ranges[j, 1]))
        corners, ranges = np.delete(corners, j, axis=0), np.delete(ranges, j, axis=0)
    return [
        (Box(x0, y0, x1 - x0, y1 - y0), (lo, hi))
        for (x0, y0, x1, y1), (lo, hi) in zip(corners.tolist(), ranges.tolist(), strict=True)
    ]


def widened(
    boxes: np.ndarray, shape: tuple[int, ...], margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(N, 4)`` boxes widened by ``margin`` of their height on every side and clipped to a
    frame of ``shape``, as corners ``x0, y0, x1, y1``; and which of them are at least 2 px wide
    and tall (the others lie outside the frame)."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    height, width = shape[:2]
    m = margin * boxes[:, 3:4]
    corners = np.hstack([boxes[:, :2] - m, boxes[:, :2] + boxes[:, 2:] + m])
    corners = np.clip(corners, 0.0, [width, height, width, height])
    usable = (corners[:, 2] - corners[:, 0] >= 2) & (corners[:, 3] - corners[:, 1] >= 2)
    return corners, usable


def _area(corners: np.ndarray) -> np.ndarray:
    return (corners[..., 2] - corners[..., 0]) * (corners[..., 3] - corners[..., 1])


def merge(parts: list[Detections], part_names: tuple[str, ...]) -> Detections:
    """One set of detections from several regions, overlapping duplicates suppressed."""
    parts = [d for d in parts if len(d)]
    if not parts:
        return Detections.empty(part_names)
    boxes = np.concatenate([d.boxes for d in parts])
    scores = np.concatenate([d.scores for d in parts])
    keep = nms(boxes, scores, 0.5)
    return Detections(
        boxes=boxes[keep],
        scores=scores[keep],
        probabilities=np.concatenate([d.probabilities for d in parts])[keep],
        parts=np.concatenate([d.parts for d in parts])[keep],
        part_names=parts[0].part_names,
    )
