"""``tracking`` dataclasses -> ``api_schemas`` models, at the service edge (DESIGN.md §2)."""

from __future__ import annotations

import math

from api_schemas.common import BoxModel
from api_schemas.tracks import FrameTracksMessage, PartState, TrackState
from tracking.tracks import PartEstimate, TrackEstimate
from tracking.types import Box


def box_model(box: Box) -> BoxModel:
    # Boxes keep at least a hundredth of a pixel of size: the schema wants positive sizes.
    return BoxModel(x=box.x, y=box.y, w=max(box.w, 0.01), h=max(box.h, 0.01))


def _unit(value: float) -> float:
    return 0.0 if not math.isfinite(value) else min(max(value, 0.0), 1.0)


def part_state(part: PartEstimate) -> PartState:
    return PartState(
        name=part.name,
        x=part.x,
        y=part.y,
        box=box_model(part.box) if part.box is not None else None,
        visible=part.visible,
        measured=part.measured,
    )


def track_state(track: TrackEstimate) -> TrackState:
    return TrackState(
        track_id=track.track_id,
        box=box_model(track.box),
        score=_unit(track.score),
        occluded=track.occluded,
        parts=[part_state(p) for p in track.parts],
        interpolated=track.interpolated,
    )


def frame_message(
    frame_index: int, timestamp: float, tracks: tuple[TrackEstimate, ...]
) -> FrameTracksMessage:
    """One frame's tracks; ``frame_index`` is the frame's position in the video."""
    return FrameTracksMessage(
        frame_index=frame_index,
        timestamp=timestamp,
        tracks=[track_state(t) for t in tracks],
    )
