"""When the tracker runs its own detector: the full frame now and then, regions of interest
around the tracks in between (DESIGN.md §5, detector scheduling)."""

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
    regions around the predicted boxes, widened by ``region_margin`` heights, which costs a
    fraction of a full search and is what keeps the tracker real-time.
    """

    def __init__(self, detector: Detector, config: PeopleTrackerConfig) -> None:
        self._detector = detector
        self._config = config
        self.reset()

    def reset(self) -> None:
        self._last_full: float | None = None

    def detect(self, frame: np.ndarray, timestamp: float, predicted: np.ndarray) -> Detections:
        c = self._config
        due = self._last_full is None or timestamp - self._last_full >= c.full_detection_interval
        if due or len(predicted) == 0:
            self._last_full = timestamp
            return self._detector.detect(frame)
        height, width = frame.shape[:2]
        found = []
        for x, y, w, h in predicted:
            m = c.region_margin * h
            x0, y0 = max(x - m, 0.0), max(y - m, 0.0)
            x1, y1 = min(x + w + m, width), min(y + h + m, height)
            if x1 - x0 < 2 or y1 - y0 < 2:
                continue
            found.append(self._detector.detect_region(frame, Box(x0, y0, x1 - x0, y1 - y0)))
        return merge(found, self._detector.part_names)


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
