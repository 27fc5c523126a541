"""Annotated MP4: the tracked frames with each person's box, id, parts and trail.

Boxes are solid for visible people and thin for occluded ones; visible parts are filled dots,
hidden parts open circles; the trail is the box's bottom centre over the last
:data:`TRAIL_SECONDS`. Written with OpenCV's ``mp4v`` (MPEG-4 part 2) codec, which every OpenCV
wheel carries, at the rate of the tracked frames.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import cv2
import numpy as np

from api_schemas.tracks import FrameTracksMessage
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo
from service.outputs.palette import track_colour

TRAIL_SECONDS = 3.0


def _bgr(track_id: int) -> tuple[int, int, int]:
    r, g, b = track_colour(track_id)
    return b, g, r


class TrackDrawer:
    """Draws tracks on frames, remembering each track's recent path for its trail."""

    def __init__(self, trail_seconds: float = TRAIL_SECONDS) -> None:
        self._trail_seconds = trail_seconds
        self._trails: dict[int, deque[tuple[float, int, int]]] = {}

    def draw(self, image_bgr: np.ndarray, message: FrameTracksMessage) -> np.ndarray:
        canvas = image_bgr.copy()
        now = message.timestamp
        for track in message.tracks:
            b = track.box
            trail = self._trails.setdefault(track.track_id, deque())
            trail.append((now, round(b.x + b.w / 2), round(b.y + b.h)))
        for track_id in list(self._trails):
            trail = self._trails[track_id]
            while trail and now - trail[0][0] > self._trail_seconds:
                trail.popleft()
            if not trail:
                del self._trails[track_id]
            elif len(trail) > 1:
                points = np.array([(x, y) for _, x, y in trail], dtype=np.int32)
                cv2.polylines(canvas, [points], False, _bgr(track_id), 1, cv2.LINE_AA)
        for track in message.tracks:
            colour = _bgr(track.track_id)
            b = track.box
            top_left = (round(b.x), round(b.y))
            bottom_right = (round(b.x + b.w), round(b.y + b.h))
            cv2.rectangle(canvas, top_left, bottom_right, colour, 1 if track.occluded else 2)
            for part in track.parts:
                centre = (round(part.x), round(part.y))
                cv2.circle(canvas, centre, 2, colour, -1 if part.visible else 1, cv2.LINE_AA)
            label = f"{track.track_id}" + (" occl" if track.occluded else "")
            (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.4, 1)
            x, y = top_left[0], max(top_left[1] - 3, th + 2)
            cv2.rectangle(canvas, (x, y - th - 2), (x + tw + 2, y + 2), colour, -1)
            cv2.putText(
                canvas, label, (x + 1, y), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1
            )
        return canvas


class VideoWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        fps = max(info.fps / info.frame_step, 1.0)
        fourcc = cv2.VideoWriter_fourcc(*"mp4v")
        self._writer = cv2.VideoWriter(str(path), fourcc, fps, (info.width, info.height))
        if not self._writer.isOpened():
            raise RuntimeError(f"OpenCV cannot write an mp4v video to {path}")
        self._size = (info.width, info.height)
        self._drawer = TrackDrawer()

    def write(self, frame: TimedFrame, message: FrameTracksMessage) -> None:
        bgr = cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR)
        if (bgr.shape[1], bgr.shape[0]) != self._size:
            bgr = cv2.resize(bgr, self._size)
        self._writer.write(self._drawer.draw(bgr, message))

    def close(self, summary: RunSummary) -> None:
        self._writer.release()

    def abort(self) -> None:
        self._writer.release()
