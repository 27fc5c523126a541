"""The Foxglove message schemas the MCAP result uses, as JSON Schema (JSON message encoding).

Field names, types and the ``PointsAnnotationType`` values follow the published
``foxglove.CompressedVideo``, ``foxglove.CompressedImage`` and ``foxglove.ImageAnnotations``
schemas (foxglove/schemas, ``schemas/jsonschema``); Foxglove's Image panel draws the
annotations over the image whose timestamp they carry.
"""

from __future__ import annotations

import base64
from typing import Any

POINTS = 1
"""``PointsAnnotationType.POINTS``: individual points."""
LINE_LOOP = 2
"""``PointsAnnotationType.LINE_LOOP``: a closed polygon."""
LINE_LIST = 4
"""``PointsAnnotationType.LINE_LIST``: a segment per pair of points."""

_TYPE_NAMES = ("UNKNOWN", "POINTS", "LINE_LOOP", "LINE_STRIP", "LINE_LIST")


def _time(description: str) -> dict[str, Any]:
    return {
        "type": "object",
        "title": "time",
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        },
        "description": description,
    }


def _point2(description: str) -> dict[str, Any]:
    return {
        "title": "foxglove.Point2",
        "description": description,
        "type": "object",
        "properties": {
            "x": {"type": "number", "description": "x coordinate position"},
            "y": {"type": "number", "description": "y coordinate position"},
        },
    }


def _color(description: str) -> dict[str, Any]:
    return {
        "title": "foxglove.Color",
        "description": description,
        "type": "object",
        "properties": {
            channel: {"type": "number", "description": f"{name} value between 0 and 1"}
            for channel, name in (("r", "Red"), ("g", "Green"), ("b", "Blue"), ("a", "Alpha"))
        },
    }


COMPRESSED_IMAGE_SCHEMA: dict[str, Any] = {
    "title": "foxglove.CompressedImage",
    "description": "A compressed image",
    "type": "object",
    "properties": {
        "timestamp": _time("Timestamp of image"),
        "frame_id": {
            "type": "string",
            "description": "Frame of reference for the image. The origin of the frame is the "
            "optical center of the camera.",
        },
        "data": {
            "type": "string",
            "contentEncoding": "base64",
            "description": "Compressed image data",
        },
        "format": {"type": "string", "description": "Image format (jpeg, png, webp)"},
    },
}

COMPRESSED_VIDEO_SCHEMA: dict[str, Any] = {
    "title": "foxglove.CompressedVideo",
    "description": "A single frame of a compressed video bitstream",
    "type": "object",
    "properties": {
        "timestamp": _time("Timestamp of video frame"),
        "frame_id": {
            "type": "string",
            "description": "Frame of reference for the video. The origin of the frame is the "
            "optical center of the camera.",
        },
        "data": {
            "type": "string",
            "contentEncoding": "base64",
            "description": "Compressed video frame data: for h264, the Annex B NAL units of "
            "exactly one frame, SPS and PPS with every key frame, no B-frames",
        },
        "format": {"type": "string", "description": "Video format (h264, h265, vp9, av1)"},
    },
}

_CIRCLE = {
    "title": "foxglove.CircleAnnotation",
    "description": "A circle annotation on a 2D image",
    "type": "object",
    "properties": {
        "timestamp": _time("Timestamp of circle"),
        "position": _point2("Center of the circle in 2D image coordinates (pixels)"),
        "diameter": {"type": "number", "description": "Circle diameter in pixels"},
        "thickness": {"type": "number", "description": "Line thickness in pixels"},
        "fill_color": _color("Fill color"),
        "outline_color": _color("Outline color"),
    },
}

_POINTS = {
    "title": "foxglove.PointsAnnotation",
    "description": "An array of points on a 2D image",
    "type": "object",
    "properties": {
        "timestamp": _time("Timestamp of annotation"),
        "type": {
            "title": "foxglove.PointsAnnotationType",
            "description": "Type of points annotation to draw",
            "oneOf": [{"title": name, "const": value} for value, name in enumerate(_TYPE_NAMES)],
        },
        "points": {
            "type": "array",
            "items": _point2("A point representing a position in 2D space"),
            "description": "Points in 2D image coordinates (pixels)",
        },
        "outline_color": _color("Outline color"),
        "outline_colors": {
            "type": "array",
            "items": _color("A color in RGBA format"),
            "description": "Per-point colors, if `type` is `POINTS`, or per-segment stroke "
            "colors, if `type` is `LINE_LIST`, `LINE_STRIP` or `LINE_LOOP`.",
        },
        "fill_color": _color("Fill color"),
        "thickness": {"type": "number", "description": "Stroke thickness in pixels"},
    },
}

_TEXT = {
    "title": "foxglove.TextAnnotation",
    "description": "A text label on a 2D image",
    "type": "object",
    "properties": {
        "timestamp": _time("Timestamp of annotation"),
        "position": _point2("Bottom-left origin of the text label in 2D image coordinates"),
        "text": {"type": "string", "description": "Text to display"},
        "font_size": {"type": "number", "description": "Font size in pixels"},
        "text_color": _color("Text color"),
        "background_color": _color("Background fill color"),
    },
}

IMAGE_ANNOTATIONS_SCHEMA: dict[str, Any] = {
    "title": "foxglove.ImageAnnotations",
    "description": "Array of annotations for a 2D image",
    "type": "object",
    "properties": {
        "circles": {"type": "array", "items": _CIRCLE, "description": "Circle annotations"},
        "points": {"type": "array", "items": _POINTS, "description": "Points annotations"},
        "texts": {"type": "array", "items": _TEXT, "description": "Text annotations"},
    },
}


def time_of(nanoseconds: int) -> dict[str, int]:
    """A ``time`` value from nanoseconds."""
    sec, nsec = divmod(int(nanoseconds), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def color(rgb: tuple[int, int, int], alpha: float = 1.0) -> dict[str, float]:
    """A ``foxglove.Color`` from 8-bit RGB."""
    r, g, b = rgb
    return {"r": r / 255.0, "g": g / 255.0, "b": b / 255.0, "a": alpha}


def compressed_image(
    nanoseconds: int, data: bytes, frame_id: str, format: str = "jpeg"
) -> dict[str, Any]:
    """A ``foxglove.CompressedImage`` or, with ``format`` "h264", ``foxglove.CompressedVideo``
    message (the two share their fields)."""
    return {
        "timestamp": time_of(nanoseconds),
        "frame_id": frame_id,
        "data": base64.b64encode(data).decode("ascii"),
        "format": format,
    }
