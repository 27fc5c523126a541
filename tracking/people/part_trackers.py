"""Per-part appearance trackers: body-part measurements for detectors without parts
(docs/architecture.md §5: "the peaks of per-part RCSK trackers")."""

from __future__ import annotations

import numpy as np

from tracking.correlation import CorrelationConfig, CorrelationTracker
from tracking.correlation.signals import subpixel_peak
from tracking.features.maps import FeatureMap
from tracking.people.body import BodyModel
from tracking.types import Box


class PartTrackers:
    """One small RCSK tracker per body part of one person.

    Each frame, every part's tracker responds around where the person's part filters predict
    the part; the peak is that part's measurement. Parts learn only where they are visible.

    Parameters
    ----------
    config:
        The RCSK configuration of every part tracker.
    body:
        Gives the parts' box sizes, in heights.
    features:
        Shared feature map (and Color Names table).
    min_peak:
        Responses below this give no measurement (the part is not recognisable there).
    """

    def __init__(
        self, config: CorrelationConfig, body: BodyModel, features: FeatureMap, min_peak: float
    ) -> None:
        self._trackers = [CorrelationTracker(config, features=features) for _ in body.names]
        self._body = body
        self._min_peak = min_peak
        self._height = 1.0

    def initialize(self, frame: np.ndarray, positions: np.ndarray, height: float) -> None:
        """Learn every part at ``positions`` ``(P, 2)`` of a person ``height`` pixels tall."""
        self._height = height
        frame_h, frame_w = frame.shape[:2]
        for tracker, (x, y), (w, h) in zip(
            self._trackers, positions, self._body.size * height, strict=True
        ):
            x = float(np.clip(x, 0, frame_w - 1))
            y = float(np.clip(y, 0, frame_h - 1))
            tracker.initialize(frame, Box.from_center(x, y, max(w, 2.0), max(h, 2.0)))

    def measure(
        self, frame: np.ndarray, expected: np.ndarray, height: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Measured part positions ``(P, 2)`` and which parts gave one ``(P,)`` bool."""
        scale = height / self._height
        found = np.zeros_like(expected)
        ok = np.zeros(len(self._trackers), dtype=bool)
        for p, tracker in enumerate(self._trackers):
            response = tracker.respond(frame, (float(expected[p, 0]), float(expected[p, 1])), scale)
            row, col, peak = subpixel_peak(response.response)
            if response.response[peak] < self._min_peak:
                continue
            rows, cols = response.response.shape
            found[p, 0] = response.center[0] + (col - cols // 2) * response.step[0]
            found[p, 1] = response.center[1] + (row - rows // 2) * response.step[1]
            ok[p] = True
        return found, ok

    def learn(
        self, frame: np.ndarray, positions: np.ndarray, height: float, visible: np.ndarray
    ) -> None:
        """Learn the visible parts at their estimated ``positions``."""
        scale = height / self._height
        for tracker, (x, y), show in zip(self._trackers, positions, visible, strict=True):
            if show:
                tracker.learn(frame, (float(x), float(y)), scale)
