"""``tracking`` arrays -> ``api_schemas`` models, once, at the service edge
(docs/architecture.md §2)."""

from __future__ import annotations

import numpy as np

from api_schemas.common import BoxModel
from api_schemas.tracks import FrameTracksMessage, PartState, TrackState
from tracking.tracks import FrameTracks


def _box_models(boxes: np.ndarray) -> list[BoxModel]:
    # Boxes keep at least a hundredth of a pixel of size: the schema wants positive sizes.
    return [
        BoxModel(x=x, y=y, w=w, h=h)
        for x, y, w, h in np.column_stack([boxes[:, :2], np.maximum(boxes[:, 2:], 0.01)]).tolist()
    ]


def frame_message(tracks: FrameTracks, frame_index: int | None = None) -> FrameTracksMessage:
    """One frame's tracks as the message every writer and subscriber reads.

    ``frame_index`` is the frame's position in the video when the pipeline numbered it
    otherwise (the pipeline counts the frames it tracked; the message counts the video's);
    by default ``tracks.frame_index``. Scores outside ``[0, 1]`` are clamped to it (not finite:
    0); part boxes with a NaN are None.
    """
    scores = tracks.scores
    unit = np.where(np.isfinite(scores), np.clip(scores, 0.0, 1.0), 0.0)
    p = len(tracks.part_names)
    part_boxes = tracks.part_boxes.reshape(-1, 4)
    has_box = ~np.isnan(part_boxes).any(axis=1)
    boxed = iter(_box_models(part_boxes[has_box]))
    parts = [
        PartState(
            name=name,
            x=x,
            y=y,
            box=next(boxed) if has else None,
            visible=visible,
            measured=measured,
        )
        for name, (x, y), has, visible, measured in zip(
            tracks.part_names * len(tracks),
            tracks.part_xy.reshape(-1, 2).tolist(),
            has_box.tolist(),
            tracks.part_visible.reshape(-1).tolist(),
            tracks.part_measured.reshape(-1).tolist(),
            strict=True,
        )
    ]
    states = [
        TrackState(
            track_id=track_id,
            box=box,
            score=score,
            occluded=occluded,
            parts=parts[row * p : (row + 1) * p],
            interpolated=interpolated,
        )
        for row, (track_id, box, score, occluded, interpolated) in enumerate(
            zip(
                tracks.track_ids.tolist(),
                _box_models(tracks.boxes),
                unit.tolist(),
                tracks.occluded.tolist(),
                tracks.interpolated.tolist(),
                strict=True,
            )
        )
    ]
    return FrameTracksMessage(
        frame_index=tracks.frame_index if frame_index is None else frame_index,
        timestamp=tracks.timestamp,
        tracks=states,
    )
