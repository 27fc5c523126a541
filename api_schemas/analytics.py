"""Zones, lines and dwell: what a job or stream watches for, and the events and counts it
reports."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from api_schemas.common import BoxModel, Pixels, RulesAcrossFields, equal

# strict numbers, as every option's: true or "1" is no coordinate
Coordinate = Annotated[float, Field(strict=True)]
Point = Annotated[
    tuple[Coordinate, Coordinate],
    Field(description="[x, y]: pixels (0-based) or, with coordinates 'normalized', 0 to 1."),
]

Name = Annotated[
    str,
    Field(
        min_length=1,
        max_length=64,
        pattern=r"^[A-Za-z0-9_.-]+$",
        description="Letters, digits, '_', '.' and '-': it names the zone or line in events, "
        "counts, MQTT topics and Zenoh keys.",
    ),
]


class ZoneOptions(BaseModel):
    """A named zone: a polygon that does not cross itself."""

    model_config = ConfigDict(extra="forbid", title="Zone", allow_inf_nan=False)

    name: Name
    polygon: list[Point] = Field(
        min_length=3, max_length=64, description="Its corners in order, 3 to 64 of them."
    )
    min_dwell: float | None = Field(
        default=None,
        strict=True,
        gt=0,
        le=86400,
        description="Seconds a person must stay inside for a 'dwell' event (unset: none).",
    )


class LineOptions(BaseModel):
    """A named directed line: a segment from its first point to its second.

    Crossing it from its left to its right, as seen looking from the first point towards the
    second on the image, counts as 'in'; the other way as 'out'.
    """

    model_config = ConfigDict(extra="forbid", title="Line", allow_inf_nan=False)

    name: Name
    # two equal points are no line: uniqueItems says so to schema readers
    points: tuple[Point, Point] = Field(
        description="[start, end]: two different points.", json_schema_extra={"uniqueItems": True}
    )

    @model_validator(mode="after")
    def _has_length(self) -> LineOptions:
        (x0, y0), (x1, y1) = self.points
        if math.hypot(x1 - x0, y1 - y0) == 0:
            raise ValueError("a line needs two different points: this one has no length")
        return self


def _unit_square(field: str) -> dict[str, Any]:
    """A JSON Schema keeping the points of each item's ``field`` (a list of points) in the
    unit square."""
    return {"items": {"properties": {field: {"items": {"items": {"minimum": 0, "maximum": 1}}}}}}


class AnalyticsOptions(RulesAcrossFields):
    """Zones and lines to watch, and how. Zone and line names must all differ (a rule JSON
    Schema cannot state)."""

    model_config = ConfigDict(extra="forbid", title="AnalyticsOptions", allow_inf_nan=False)
    schema_rules = (
        {
            "if": equal("coordinates", "normalized"),
            "then": {
                "properties": {
                    "zones": _unit_square("polygon"),
                    "lines": _unit_square("points"),
                }
            },
        },
    )

    coordinates: Literal["pixels", "normalized"] = Field(
        default="pixels",
        description="'pixels' of the video's frames, or 'normalized': 0 to 1 across its width "
        "and height, which fits any resolution of the same camera.",
    )
    zones: list[ZoneOptions] = Field(default_factory=list, max_length=32)
    lines: list[LineOptions] = Field(default_factory=list, max_length=32)
    hysteresis: float = Field(
        default=0.1,
        strict=True,
        ge=0,
        le=1,
        description="Half-width of the band around lines and zone edges where a person keeps "
        "their side, as a fraction of their height: someone standing on a line does not "
        "cross it back and forth.",
    )
    bucket_seconds: float = Field(
        default=60,
        strict=True,
        ge=1,
        le=86400,
        description="Length of the time buckets of the counts.",
    )

    @model_validator(mode="after")
    def _names_and_coordinates(self) -> AnalyticsOptions:
        names = [z.name for z in self.zones] + [line.name for line in self.lines]
        if twice := sorted({n for n in names if names.count(n) > 1}):
            raise ValueError(f"zone and line names must differ: {', '.join(twice)} repeats")
        if self.coordinates == "normalized":
            points = [p for z in self.zones for p in z.polygon]
            points += [p for line in self.lines for p in line.points]
            if any(not (0 <= v <= 1) for p in points for v in p):
                raise ValueError("normalized coordinates lie between 0 and 1")
        return self


EventType = Literal["line_crossed", "zone_entered", "zone_left", "dwell"]


class AnalyticsEvent(BaseModel):
    """Something a person did at a line or zone."""

    model_config = ConfigDict(title="AnalyticsEvent")

    type: EventType
    name: str = Field(description="The line or zone.")
    track_id: int = Field(ge=0)
    timestamp: float = Field(description="Capture time of the frame, in seconds.")
    frame_index: int = Field(ge=0, description="The frame, 0-based.")
    position: tuple[Pixels, Pixels] = Field(description="The person's ground point [x, y].")
    box: BoxModel
    direction: Literal["in", "out"] | None = Field(
        default=None, description="For line_crossed: 'in' from the line's left to its right."
    )
    dwell_seconds: float | None = Field(
        default=None, description="For dwell and zone_left: seconds spent in the zone."
    )
    lost: bool = Field(
        default=False, description="For zone_left: the person was no longer seen, not seen out."
    )


class CameraEvent(AnalyticsEvent):
    """An event of a live stream: what ``<prefix>/cameras/<camera>/events`` carries (JSON),
    and the body of its webhook requests and MQTT messages."""

    model_config = ConfigDict(title="CameraEvent")

    camera: str = Field(description="The camera's name.")


class LineCounts(BaseModel):
    # "in" is a Python keyword: the field is in_, named "in" in JSON both ways
    model_config = ConfigDict(
        title="LineCounts", validate_by_name=True, validate_by_alias=True, serialize_by_alias=True
    )

    in_: int = Field(alias="in", ge=0, description="Crossings from the line's left to its right.")
    out: int = Field(ge=0, description="Crossings the other way.")


class ZoneCounts(BaseModel):
    model_config = ConfigDict(title="ZoneCounts")

    entered: int = Field(ge=0)
    left: int = Field(ge=0)
    dwell: int = Field(ge=0)


class CountsBucket(BaseModel):
    model_config = ConfigDict(title="CountsBucket")

    start: float = Field(description="Start of the bucket, seconds of capture time.")
    lines: dict[str, LineCounts] = Field(default_factory=dict)
    zones: dict[str, ZoneCounts] = Field(default_factory=dict)


class AnalyticsCounts(BaseModel):
    """Counts over the whole job or stream and per time bucket."""

    model_config = ConfigDict(title="AnalyticsCounts")

    lines: dict[str, LineCounts] = Field(default_factory=dict)
    zones: dict[str, ZoneCounts] = Field(default_factory=dict)
    buckets: list[CountsBucket] = Field(default_factory=list)


class AnalyticsResult(BaseModel):
    """What a job's zones and lines saw: in its JSON result, and alone as ``analytics.json``
    (``GET /v1/jobs/{id}/analytics``). Zones and lines in pixels of the video, as they ran."""

    model_config = ConfigDict(title="AnalyticsResult")

    zones: list[ZoneOptions] = Field(default_factory=list)
    lines: list[LineOptions] = Field(default_factory=list)
    events: list[AnalyticsEvent] = Field(default_factory=list, description="In time order.")
    counts: AnalyticsCounts = Field(default_factory=AnalyticsCounts)
