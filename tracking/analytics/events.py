"""Events and counts from trajectories: people crossing lines, entering, leaving and dwelling
in zones, computed frame by frame as the tracker reports (the same code for uploads and live
streams).

A person's position is their ground point (:func:`ground_points`): between the ankles when the
pose network placed them, else the bottom centre of the box. Around every line and zone
boundary lies a band as wide as a fraction of the person's height
(:attr:`AnalyticsConfig.hysteresis`): inside it a person keeps the side they had, so that
someone standing on a line, whose ground point jitters by a few pixels from frame to frame,
does not cross it back and forth (the hysteresis of a Schmitt trigger).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from tracking.analytics.geometry import (
    segments_cross,
    side_distance,
    signed_distance_to_polygon,
)

__all__ = [
    "AnalyticsConfig",
    "AnalyticsEngine",
    "Counts",
    "Event",
    "EventType",
    "Line",
    "Zone",
    "ground_points",
]

EventType = Literal["line_crossed", "zone_entered", "zone_left", "dwell"]
_EVENT_ORDER = ("line_crossed", "zone_left", "zone_entered", "dwell")
_STATE = ("_ids", "_last_seen", "_point", "_box", "_side", "_anchor", "_inside", "_since", "_dwelt")
"""The engine's arrays with a row per person."""


@dataclass(frozen=True, slots=True)
class Zone:
    """A named zone: a simple polygon ``(K, 2)`` in pixels; ``min_dwell`` seconds inside it
    make a ``dwell`` event (None: no dwell events)."""

    name: str
    polygon: np.ndarray
    min_dwell: float | None = None


@dataclass(frozen=True, slots=True)
class Line:
    """A named directed line from ``start`` to ``end`` ``(2,)`` in pixels.

    Crossing it from its left to its right, as seen looking from ``start`` towards ``end`` on
    the image, is ``in``; the other way is ``out``. Only the segment counts: passing beyond
    its ends crosses nothing.
    """

    name: str
    start: np.ndarray
    end: np.ndarray


@dataclass(frozen=True, slots=True)
class AnalyticsConfig:
    """What to watch and how.

    Attributes
    ----------
    zones, lines:
        The zones and lines, in pixels.
    hysteresis:
        Half-width of the band around lines and zone boundaries where a person keeps their
        side, as a fraction of the person's box height (0.1: about 17 cm for a 1.7 m person,
        whatever their distance from the camera).
    forget_after:
        Seconds a person may go unseen (occluded, between detections) and keep their state;
        then they are forgotten, and leave the zones they were in (``zone_left``, ``lost``).
    bucket_seconds:
        Length of the time buckets of :class:`Counts`.
    """

    zones: tuple[Zone, ...] = ()
    lines: tuple[Line, ...] = ()
    hysteresis: float = 0.1
    forget_after: float = 5.0
    bucket_seconds: float = 60.0


@dataclass(frozen=True, slots=True)
class Event:
    """Something a person did at a line or zone.

    ``direction`` is ``in`` or ``out`` for ``line_crossed``; ``dwell_seconds`` the time spent
    in the zone for ``dwell`` and ``zone_left``; ``lost`` true for a ``zone_left`` of a person
    who was no longer seen rather than seen outside.
    """

    type: EventType
    name: str
    track_id: int
    timestamp: float
    position: tuple[float, float]
    box: tuple[float, float, float, float]
    direction: Literal["in", "out"] | None = None
    dwell_seconds: float | None = None
    lost: bool = False


@dataclass(slots=True)
class Counts:
    """Running counts: per line ``{"in": n, "out": n}``, per zone ``{"entered": n, "left": n,
    "dwell": n}``, in total and per time bucket (keyed by the bucket's start in seconds)."""

    lines: dict[str, dict[str, int]] = field(default_factory=dict)
    zones: dict[str, dict[str, int]] = field(default_factory=dict)
    buckets: dict[float, Counts] = field(default_factory=dict)

    def add(self, event: Event, bucket_seconds: float | None = None) -> None:
        if event.type == "line_crossed":
            line = self.lines.setdefault(event.name, {"in": 0, "out": 0})
            line[str(event.direction)] += 1
        else:
            key = {"zone_entered": "entered", "zone_left": "left", "dwell": "dwell"}[event.type]
            zone = self.zones.setdefault(event.name, {"entered": 0, "left": 0, "dwell": 0})
            zone[key] += 1
        if bucket_seconds is not None:
            start = float(np.floor(event.timestamp / bucket_seconds) * bucket_seconds)
            self.buckets.setdefault(start, Counts()).add(event)


def ground_points(
    boxes: np.ndarray,
    part_names: tuple[str, ...] = (),
    part_xy: np.ndarray | None = None,
    part_placed: np.ndarray | None = None,
) -> np.ndarray:
    """Where each person ``(N,)`` stands, ``(N, 2)``: the mean of the ankles a measurement
    placed (``part_placed`` ``(N, P)``: visible and measured), else the box's bottom centre.

    ``boxes`` ``(N, 4)`` ``x, y, w, h``; ``part_xy`` ``(N, P, 2)`` in the order of
    ``part_names``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    points = np.column_stack([boxes[:, 0] + boxes[:, 2] / 2, boxes[:, 1] + boxes[:, 3]])
    ankles = [i for i, name in enumerate(part_names) if name in ("left_ankle", "right_ankle")]
    if not ankles or part_xy is None or part_placed is None or not len(boxes):
        return points
    placed = np.asarray(part_placed, dtype=bool)[:, ankles]  # (N, A)
    xy = np.asarray(part_xy, dtype=np.float64)[:, ankles]  # (N, A, 2)
    count = placed.sum(axis=1)
    mean = (xy * placed[..., None]).sum(axis=1) / np.maximum(count, 1)[:, None]
    return np.where((count > 0)[:, None], mean, points)


class AnalyticsEngine:
    """Events and counts of one video or camera, fed one frame at a time.

    The state of every person seen lately lives in arrays with a row per person (their line
    sides, the point where each side was last confirmed, whether they are in each zone and
    since when), so that a frame's people are handled together.
    """

    def __init__(self, config: AnalyticsConfig) -> None:
        self.config = config
        self.counts = Counts()
        n_lines, n_zones = len(config.lines), len(config.zones)
        self._ids = np.zeros(0, dtype=np.int64)
        self._last_seen = np.zeros(0)
        self._point = np.zeros((0, 2))
        self._box = np.zeros((0, 4))
        self._side = np.zeros((0, n_lines), dtype=np.int8)  # -1 left, +1 right, 0 not yet
        self._anchor = np.zeros((0, n_lines, 2))  # where the side was last confirmed
        self._inside = np.zeros((0, n_zones), dtype=bool)
        self._since = np.zeros((0, n_zones))
        self._dwelt = np.zeros((0, n_zones), dtype=bool)

    def update(
        self,
        timestamp: float,
        track_ids: np.ndarray,
        points: np.ndarray,
        boxes: np.ndarray,
    ) -> list[Event]:
        """The events of one frame: its people's ids ``(N,)``, ground points ``(N, 2)``
        (:func:`ground_points`) and boxes ``(N, 4)``, captured at ``timestamp`` seconds.

        Events come in a fixed order: crossings, zones left, entered, dwells; each by line or
        zone as configured, then in the order of the frame's people.
        """
        ids = np.asarray(track_ids, dtype=np.int64).reshape(-1)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        events = self._forget(timestamp, keep=ids)
        rows = self._rows(ids)
        band = self.config.hysteresis * boxes[:, 3]
        for index, line in enumerate(self.config.lines):
            events += self._cross(index, line, rows, ids, points, boxes, band, timestamp)
        for index, zone in enumerate(self.config.zones):
            events += self._zone(index, zone, rows, ids, points, boxes, band, timestamp)
        self._last_seen[rows] = timestamp
        self._point[rows] = points
        self._box[rows] = boxes
        events.sort(key=lambda e: _EVENT_ORDER.index(e.type))  # stable: name, then id order
        for event in events:
            self.counts.add(event, self.config.bucket_seconds)
        return events

    def _rows(self, ids: np.ndarray) -> np.ndarray:
        """The state rows of ``ids``, new rows added for people not seen before."""
        new = ids[~np.isin(ids, self._ids)]
        if len(new):
            n, lines, zones = len(new), len(self.config.lines), len(self.config.zones)
            self._ids = np.concatenate([self._ids, new])
            self._last_seen = np.concatenate([self._last_seen, np.zeros(n)])
            self._point = np.concatenate([self._point, np.zeros((n, 2))])
            self._box = np.concatenate([self._box, np.zeros((n, 4))])
            self._side = np.concatenate([self._side, np.zeros((n, lines), np.int8)])
            self._anchor = np.concatenate([self._anchor, np.zeros((n, lines, 2))])
            self._inside = np.concatenate([self._inside, np.zeros((n, zones), bool)])
            self._since = np.concatenate([self._since, np.zeros((n, zones))])
            self._dwelt = np.concatenate([self._dwelt, np.zeros((n, zones), bool)])
        order = np.argsort(self._ids)
        return order[np.searchsorted(self._ids, ids, sorter=order)]

    def _cross(
        self,
        index: int,
        line: Line,
        rows: np.ndarray,
        ids: np.ndarray,
        points: np.ndarray,
        boxes: np.ndarray,
        band: np.ndarray,
        timestamp: float,
    ) -> list[Event]:
        """Crossings of ``line`` (the ``index`` th) by the frame's people, whose state rows
        are ``rows``; ``band`` ``(N,)`` is each one's hysteresis in pixels."""
        distance = side_distance(points, line.start, line.end)
        side = np.where(distance > band, 1, np.where(distance < -band, -1, 0)).astype(np.int8)
        before = self._side[rows, index]
        switched = (side != 0) & (before != 0) & (side != before)
        # the path since the side was last confirmed must pass through the segment itself
        through = segments_cross(
            self._anchor[rows, index], points, line.start[None], line.end[None], strict=False
        )
        crossed = np.flatnonzero(switched & through)
        settled = side != 0
        self._side[rows[settled], index] = side[settled]
        self._anchor[rows[settled], index] = points[settled]
        return [
            _event(
                "line_crossed",
                line.name,
                ids[i],
                timestamp,
                points[i],
                boxes[i],
                direction="in" if side[i] > 0 else "out",
            )
            for i in crossed
        ]

    def _zone(
        self,
        index: int,
        zone: Zone,
        rows: np.ndarray,
        ids: np.ndarray,
        points: np.ndarray,
        boxes: np.ndarray,
        band: np.ndarray,
        timestamp: float,
    ) -> list[Event]:
        """People entering, leaving and dwelling in ``zone`` (the ``index`` th)."""
        depth = signed_distance_to_polygon(points, zone.polygon)
        before = self._inside[rows, index]
        inside = np.where(depth > band, True, np.where(depth < -band, False, before))
        entered, left = inside & ~before, before & ~inside
        stayed = timestamp - self._since[rows, index]
        events = [
            _event(
                "zone_left",
                zone.name,
                ids[i],
                timestamp,
                points[i],
                boxes[i],
                dwell_seconds=float(stayed[i]),
            )
            for i in np.flatnonzero(left)
        ]
        events += [
            _event("zone_entered", zone.name, ids[i], timestamp, points[i], boxes[i])
            for i in np.flatnonzero(entered)
        ]
        self._since[rows[entered], index] = timestamp
        self._inside[rows, index] = inside
        self._dwelt[rows[~inside], index] = False
        if zone.min_dwell is not None:
            stayed = timestamp - self._since[rows, index]
            # a hair's allowance: capture times are sums of float periods
            dwell = inside & ~self._dwelt[rows, index] & (stayed >= zone.min_dwell - 1e-9)
            self._dwelt[rows[dwell], index] = True
            events += [
                _event(
                    "dwell",
                    zone.name,
                    ids[i],
                    timestamp,
                    points[i],
                    boxes[i],
                    dwell_seconds=float(stayed[i]),
                )
                for i in np.flatnonzero(dwell)
            ]
        return events

    def _forget(self, timestamp: float, keep: np.ndarray) -> list[Event]:
        """Drop the people unseen for longer than ``forget_after``; they leave their zones."""
        gone = (timestamp - self._last_seen > self.config.forget_after) & ~np.isin(self._ids, keep)
        if not gone.any():
            return []
        events = [
            _event(
                "zone_left",
                zone.name,
                self._ids[row],
                timestamp,
                self._point[row],
                self._box[row],
                dwell_seconds=float(self._last_seen[row] - self._since[row, index]),
                lost=True,
            )
            for index, zone in enumerate(self.config.zones)
            for row in np.flatnonzero(gone & self._inside[:, index])
        ]
        kept = ~gone
        for name in _STATE:
            setattr(self, name, getattr(self, name)[kept])
        return events


def _event(
    kind: EventType,
    name: str,
    track_id: np.integer | int,
    timestamp: float,
    point: np.ndarray,
    box: np.ndarray,
    *,
    direction: Literal["in", "out"] | None = None,
    dwell_seconds: float | None = None,
    lost: bool = False,
) -> Event:
    x, y = (float(v) for v in point)
    bx, by, bw, bh = (float(v) for v in box)
    return Event(
        kind,
        name,
        int(track_id),
        float(timestamp),
        (x, y),
        (bx, by, bw, bh),
        direction=direction,
        dwell_seconds=dwell_seconds,
        lost=lost,
    )
