"""Zones and lines of a job or stream: their options checked against the video and turned into
the engine's configuration (:mod:`tracking.analytics`), the engine driven by the tracker's
frames, and its events and counts as ``api_schemas`` models (which
:mod:`service.delivery.messages` sends on).
"""

from __future__ import annotations

import numpy as np

from api_schemas.analytics import (
    AnalyticsCounts,
    AnalyticsEvent,
    AnalyticsOptions,
    AnalyticsResult,
    CountsBucket,
    LineCounts,
    LineOptions,
    ZoneCounts,
    ZoneOptions,
)
from api_schemas.common import BoxModel
from tracking.analytics import (
    AnalyticsConfig,
    AnalyticsEngine,
    Counts,
    Event,
    Line,
    Zone,
    ground_points,
    polygon_problem,
)
from tracking.tracks import FrameTracks

__all__ = [
    "AnalyticsProblem",
    "FrameAnalytics",
    "analytics_config",
    "counts_model",
    "engine_counts",
]


class AnalyticsProblem(ValueError):
    """Zones or lines that cannot be watched in this video; ``loc`` names the field."""

    def __init__(self, loc: tuple[str | int, ...], message: str) -> None:
        super().__init__(f"{'.'.join(map(str, loc))}: {message}")
        self.loc = loc
        self.message = message


def analytics_config(
    options: AnalyticsOptions, frame_size: tuple[int, int] | None = None
) -> AnalyticsConfig:
    """The engine's configuration of ``options`` on frames of ``frame_size`` (width, height).

    Normalised coordinates need the frame size; without it (a stream before its first frame)
    they are checked in the unit square. Raises :class:`AnalyticsProblem` for a zone whose
    edges cross, that has no area, or that lies wholly outside the frame, and for a line
    wholly outside it.
    """
    extent = None if frame_size is None else np.array(frame_size, dtype=np.float64)
    scale = extent if options.coordinates == "normalized" and extent is not None else np.ones(2)
    zones = []
    for index, zone in enumerate(options.zones):
        polygon = np.array(zone.polygon, dtype=np.float64) * scale
        where = ("analytics", "zones", index, "polygon")
        if problem := polygon_problem(polygon):
            raise AnalyticsProblem(where, problem)
        if extent is not None and _outside(polygon, extent):
            raise AnalyticsProblem(where, _outside_message("zone", extent))
        zones.append(Zone(zone.name, polygon, zone.min_dwell))
    lines = []
    for index, line in enumerate(options.lines):
        points = np.array(line.points, dtype=np.float64) * scale
        if extent is not None and _outside(points, extent):
            where = ("analytics", "lines", index, "points")
            raise AnalyticsProblem(where, _outside_message("line", extent))
        lines.append(Line(line.name, points[0], points[1]))
    return AnalyticsConfig(
        zones=tuple(zones),
        lines=tuple(lines),
        hysteresis=options.hysteresis,
        bucket_seconds=options.bucket_seconds,
    )


def _outside(points: np.ndarray, extent: np.ndarray) -> bool:
    """Whether the bounding box of ``points`` misses the frame ``[0, w] x [0, h]``."""
    low, high = points.min(axis=0), points.max(axis=0)
    return bool(np.any(high < 0) or np.any(low > extent))


def _outside_message(what: str, extent: np.ndarray) -> str:
    width, height = (int(v) for v in extent)
    return (
        f"the {what} lies wholly outside the {width}x{height} frame: pixel coordinates run "
        f"from 0 to {width} across and 0 to {height} down (or use coordinates 'normalized')"
    )


class FrameAnalytics:
    """The engine fed with the tracker's frames; events as ``api_schemas`` models, kept for
    :meth:`result` (``keep``: a job's; a stream sends its events on instead)."""

    def __init__(self, config: AnalyticsConfig, keep: bool = True) -> None:
        self.config = config
        self.engine = AnalyticsEngine(config)
        self.events: list[AnalyticsEvent] = []
        self._keep = keep

    def update(self, tracks: FrameTracks, frame_index: int | None = None) -> list[AnalyticsEvent]:
        """The events of one frame (numbered ``frame_index``, default its own index)."""
        placed = tracks.part_visible & tracks.part_measured
        points = ground_points(tracks.boxes, tracks.part_names, tracks.part_xy, placed)
        events = self.engine.update(tracks.timestamp, tracks.track_ids, points, tracks.boxes)
        index = tracks.frame_index if frame_index is None else frame_index
        models = [event_model(event, index) for event in events]
        if self._keep:
            self.events.extend(models)
        return models

    def counts(self) -> AnalyticsCounts:
        return counts_model(self.engine.counts)

    def result(self) -> AnalyticsResult:
        """Zones and lines (in pixels, as they ran), every event and the counts."""
        zones = [
            ZoneOptions(name=z.name, polygon=z.polygon.tolist(), min_dwell=z.min_dwell)
            for z in self.config.zones
        ]
        lines = [
            LineOptions(name=line.name, points=(line.start.tolist(), line.end.tolist()))
            for line in self.config.lines
        ]
        return AnalyticsResult(zones=zones, lines=lines, events=self.events, counts=self.counts())


def event_model(event: Event, frame_index: int) -> AnalyticsEvent:
    x, y, w, h = event.box
    return AnalyticsEvent(
        type=event.type,
        name=event.name,
        track_id=event.track_id,
        timestamp=event.timestamp,
        frame_index=frame_index,
        position=event.position,
        box=BoxModel(x=x, y=y, w=max(w, 0.01), h=max(h, 0.01)),
        direction=event.direction,
        dwell_seconds=event.dwell_seconds,
        lost=event.lost,
    )


def engine_counts(counts: AnalyticsCounts) -> Counts:
    """The totals of ``counts`` as the engine keeps them (:func:`counts_model` undone, the
    buckets aside): for holding a job's counts against others' with
    :func:`tracking.evaluation.counting.count_error`."""
    return Counts(
        lines={name: c.model_dump(by_alias=True) for name, c in counts.lines.items()},
        zones={name: c.model_dump() for name, c in counts.zones.items()},
    )


def counts_model(counts: Counts) -> AnalyticsCounts:
    def lines(c: Counts) -> dict[str, LineCounts]:
        return {name: LineCounts.model_validate(n) for name, n in c.lines.items()}

    def zones(c: Counts) -> dict[str, ZoneCounts]:
        return {name: ZoneCounts.model_validate(n) for name, n in c.zones.items()}

    return AnalyticsCounts(
        lines=lines(counts),
        zones=zones(counts),
        buckets=[
            CountsBucket(start=start, lines=lines(bucket), zones=zones(bucket))
            for start, bucket in sorted(counts.buckets.items())
        ],
    )
