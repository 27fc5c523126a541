"""Zones, lines and dwell: events and counts computed from the tracks, frame by frame."""

from tracking.analytics.events import (
    AnalyticsConfig,
    AnalyticsEngine,
    Counts,
    Event,
    EventType,
    Line,
    Zone,
    ground_points,
)
from tracking.analytics.geometry import polygon_problem

__all__ = [
    "AnalyticsConfig",
    "AnalyticsEngine",
    "Counts",
    "Event",
    "EventType",
    "Line",
    "Zone",
    "ground_points",
    "polygon_problem",
]
