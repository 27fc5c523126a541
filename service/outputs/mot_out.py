"""MOTChallenge text: ``frame,id,x,y,w,h,score,-1,-1,-1`` per track and frame.

MOTChallenge's own conventions, so that the file scores against a ``gt.txt`` as it is (TrackEval,
the MOTChallenge devkit): frames count from 1 (the video's first frame is frame 1) and so do
pixels: ``x`` and ``y`` are the JSON result's 0-based corner plus 1
(:func:`tracking.detection.sequences.image_to_mot_boxes`).
"""

from __future__ import annotations

from pathlib import Path

from api_schemas.tracks import FrameTracksMessage
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo
from tracking.detection.sequences import image_to_mot_boxes


def mot_rows(message: FrameTracksMessage) -> list[str]:
    boxes = image_to_mot_boxes([[t.box.x, t.box.y, t.box.w, t.box.h] for t in message.tracks])
    return [
        f"{message.frame_index + 1},{track.track_id},{x:.2f},{y:.2f},{w:.2f},{h:.2f},"
        f"{track.score:.4f},-1,-1,-1"
        for track, (x, y, w, h) in zip(message.tracks, boxes.tolist(), strict=True)
    ]


class MotWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        self._file = path.open("w", encoding="utf-8")

    def write(self, frame: TimedFrame, message: FrameTracksMessage) -> None:
        self._append(message)

    def write_filled(self, message: FrameTracksMessage) -> None:
        # rows of filled frames come when the gap closes, after later frames' rows: MOT
        # readers group rows by frame, so the file needs no order
        self._append(message)

    def _append(self, message: FrameTracksMessage) -> None:
        self._file.writelines(row + "\n" for row in mot_rows(message))

    def close(self, summary: RunSummary) -> None:
        self._file.close()

    def abort(self) -> None:
        self._file.close()
