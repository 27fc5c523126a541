"""MOTChallenge text: ``frame,id,x,y,w,h,score,-1,-1,-1`` per track and frame.

Frames count from 1 (the video's first frame is frame 1), as evaluation tools (TrackEval, the
MOTChallenge devkit) expect; boxes are pixels with a 0-based top-left corner, as in the
benchmark's own files.
"""

from __future__ import annotations

from pathlib import Path

from api_schemas.tracks import FrameTracksMessage
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo


def mot_rows(message: FrameTracksMessage) -> list[str]:
    rows = []
    for track in message.tracks:
        b = track.box
        rows.append(
            f"{message.frame_index + 1},{track.track_id},{b.x:.2f},{b.y:.2f},{b.w:.2f},{b.h:.2f},"
            f"{track.score:.4f},-1,-1,-1"
        )
    return rows


class MotWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        self._file = path.open("w", encoding="utf-8")

    def write(self, frame: TimedFrame, message: FrameTracksMessage) -> None:
        for row in mot_rows(message):
            self._file.write(row + "\n")

    def close(self, summary: RunSummary) -> None:
        self._file.close()

    def abort(self) -> None:
        self._file.close()
