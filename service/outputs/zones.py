"""Zones and lines as the MP4 and the MCAP draw them: outlines, a direction arrow on each
line, and labels with the running counts, from the events of each frame."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from api_schemas.analytics import AnalyticsEvent
from tracking.analytics import AnalyticsConfig

ZONE_RGB = (255, 200, 0)
LINE_RGB = (0, 220, 255)


@dataclass(frozen=True, slots=True)
class Label:
    """A text at ``(x, y)``, in pixels (its baseline's left end)."""

    x: float
    y: float
    text: str


class ZoneOverlay:
    """The zones and lines of ``config`` with the counts of the events seen so far."""

    def __init__(self, config: AnalyticsConfig) -> None:
        self.config = config
        self._lines = {line.name: {"in": 0, "out": 0} for line in config.lines}
        self._zones = {zone.name: {"entered": 0, "inside": 0} for zone in config.zones}

    def update(self, events: Sequence[AnalyticsEvent]) -> None:
        """Count a frame's events."""
        for event in events:
            if event.type == "line_crossed" and event.direction is not None:
                self._lines[event.name][event.direction] += 1
            elif event.type == "zone_entered":
                self._zones[event.name]["entered"] += 1
                self._zones[event.name]["inside"] += 1
            elif event.type == "zone_left":
                self._zones[event.name]["inside"] -= 1

    def polygons(self) -> list[np.ndarray]:
        """Each zone's corners, ``(K, 2)``."""
        return [zone.polygon for zone in self.config.zones]

    def segments(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each line, then its arrow: a short stroke from the line's middle towards the side a
        person crossing 'in' goes to (the line's right, looking along it on the image)."""
        drawn = []
        for line in self.config.lines:
            direction = line.end - line.start
            middle = (line.start + line.end) / 2
            # right of the direction of travel on the image (y down): rotate by -90 degrees
            right = np.array([-direction[1], direction[0]]) / max(np.hypot(*direction), 1e-9)
            drawn += [(line.start, line.end), (middle, middle + 15.0 * right)]
        return drawn

    def labels(self) -> list[Label]:
        """A label per line (``gate: in 3 out 1``) at its start and per zone
        (``bench: 2 in, 5 entered``) at its top corner."""
        labels = []
        for line in self.config.lines:
            counts = self._lines[line.name]
            text = f"{line.name}: in {counts['in']} out {counts['out']}"
            labels.append(Label(float(line.start[0]), float(line.start[1]) - 4, text))
        for zone in self.config.zones:
            top = zone.polygon[np.argmin(zone.polygon[:, 1])]
            counts = self._zones[zone.name]
            text = f"{zone.name}: {counts['inside']} in, {counts['entered']} entered"
            labels.append(Label(float(top[0]), float(top[1]) - 4, text))
        return labels
