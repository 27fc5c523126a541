"""What a tracking pipeline says about one frame: plain dataclasses, converted to `api_schemas`
models only at the service edge."""

from __future__ import annotations

from dataclasses import dataclass

from tracking.types import Box

__all__ = ["FrameTracks", "PartEstimate", "TrackEstimate"]


@dataclass(frozen=True, slots=True)
class PartEstimate:
    """One body part of a tracked person.

    Attributes
    ----------
    name:
        Stable part name (``"head"``, ``"left_shoulder"``...).
    x, y:
        Centre of the part in pixels.
    box:
        The part's box, when the model gives one.
    visible:
        ``False`` when the part is covered (by another person) or out of the frame; its position
        is then the model's prediction, not a measurement.
    measured:
        ``True`` when a measurement of this frame placed the part (a DPM part placement, or the
        peak of the part's own tracker); ``False`` when its position is the body model's
        prediction from the person's box, which is all a detector without parts gives.
    """

    name: str
    x: float
    y: float
    box: Box | None
    visible: bool
    measured: bool = False


@dataclass(frozen=True, slots=True)
class TrackEstimate:
    """One tracked object in one frame.

    Attributes
    ----------
    track_id:
        Stable id of the object within one pipeline (one video or one camera stream).
    box:
        Estimated box.
    score:
        Confidence in ``[0, 1]`` that the box holds the object.
    occluded:
        ``True`` while another, nearer object covers it.
    parts:
        Body parts, empty for trackers without parts.
    interpolated:
        ``True`` when the tracker did not report the object in this frame and the estimate
        was filled in afterwards between two frames where it did
        (:mod:`tracking.gap_filling`).
    """

    track_id: int
    box: Box
    score: float
    occluded: bool
    parts: tuple[PartEstimate, ...] = ()
    interpolated: bool = False


@dataclass(frozen=True, slots=True)
class FrameTracks:
    """Everything tracked in one frame.

    Attributes
    ----------
    frame_index:
        0-based index of the frame in its video or stream (as processed; skipped stream frames
        leave gaps).
    timestamp:
        Capture time of the frame in seconds (video position for files, the camera's clock for
        streams).
    tracks:
        The objects in view.
    """

    frame_index: int
    timestamp: float
    tracks: tuple[TrackEstimate, ...]
