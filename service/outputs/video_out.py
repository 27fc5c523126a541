"""Annotated MP4: the tracked frames with each person's box, id, parts, limbs and trail.

Boxes are solid for visible people and thin for occluded ones; parts the frame placed (visible
and measured) are filled dots, predicted ones (covered, or not measured) open circles; the
skeleton's limbs are thin lines between two visible parts, under the dots; the trail is the
box's bottom centre over the last :data:`TRAIL_SECONDS`.

The video is H.264 (:mod:`service.outputs.h264`), 4:2:0, with its index at the front of the
file, so browsers and phones play it and start before the download ends; each frame keeps its
presentation time, so a variable-frame-rate source and ``frame_step`` keep their timing. Where
PyAV has no H.264 encoder, the video is OpenCV's ``mp4v`` (MPEG-4 part 2) at the nominal rate
of the tracked frames: desktop players open it, browsers do not.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from api_schemas.analytics import AnalyticsEvent
from api_schemas.tracks import FrameTracksMessage
from service.ffmpeg_paths import FfmpegPath
from service.frames import TimedFrame
from service.outputs import h264
from service.outputs.base import RunSummary, StreamInfo, limbs
from service.outputs.h264 import H264_OPTIONS, FrameStamper, configure
from service.outputs.palette import track_colour
from service.outputs.zones import LINE_RGB, ZONE_RGB, ZoneOverlay

log = logging.getLogger(__name__)

TRAIL_SECONDS = 3.0


def _bgr(track_id: int) -> tuple[int, int, int]:
    r, g, b = track_colour(track_id)
    return b, g, r


class TrackDrawer:
    """Draws tracks on frames, remembering each track's recent path for its trail;
    ``skeleton`` the pairs of part names drawn as limbs."""

    def __init__(
        self,
        trail_seconds: float = TRAIL_SECONDS,
        skeleton: tuple[tuple[str, str], ...] = (),
    ) -> None:
        self._trail_seconds = trail_seconds
        self._skeleton = skeleton
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
            for (x0, y0), (x1, y1) in limbs(track, self._skeleton):
                ends = (round(x0), round(y0)), (round(x1), round(y1))
                cv2.line(canvas, *ends, colour, 1, cv2.LINE_AA)
            for part in track.parts:
                centre = (round(part.x), round(part.y))
                filled = -1 if part.visible and part.measured else 1
                cv2.circle(canvas, centre, 2, colour, filled, cv2.LINE_AA)
            label = f"{track.track_id}" + (" occl" if track.occluded else "")
            (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.4, 1)
            x, y = top_left[0], max(top_left[1] - 3, th + 2)
            cv2.rectangle(canvas, (x, y - th - 2), (x + tw + 2, y + 2), colour, -1)
            cv2.putText(
                canvas, label, (x + 1, y), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1
            )
        return canvas


def draw_zones(canvas: np.ndarray, overlay: ZoneOverlay) -> None:
    """Draw the zones, the lines with their 'in' arrows, and the running counts on ``canvas``
    (BGR, in place)."""
    zone_bgr, line_bgr = ZONE_RGB[::-1], LINE_RGB[::-1]
    polygons = [np.round(p).astype(np.int32) for p in overlay.polygons()]
    cv2.polylines(canvas, polygons, True, zone_bgr, 2, cv2.LINE_AA)
    for start, end in overlay.segments():
        a, b = tuple(int(v) for v in np.round(start)), tuple(int(v) for v in np.round(end))
        cv2.line(canvas, a, b, line_bgr, 2, cv2.LINE_AA)
    for label in overlay.labels():
        origin = (round(label.x), max(round(label.y), 12))
        cv2.putText(canvas, label.text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 3)
        cv2.putText(canvas, label.text, origin, cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1)


class _Encoder(Protocol):
    def write(self, bgr: np.ndarray, timestamp: float) -> None: ...

    def close(self) -> None: ...


class H264Encoder:
    """BGR frames to an H.264 MP4 (PyAV's libx264), each at its presentation time, with the
    source's pixel aspect ratio, so players show non-square pixels (PAL D1 recorders) as the
    source plays."""

    def __init__(
        self, path: Path, width: int, height: int, fps: float, pixel_aspect: float = 1.0
    ) -> None:
        import av

        self._frames = FrameStamper("bgr24")
        self._path = FfmpegPath(path, writing=True)
        try:
            self._container = av.open(
                self._path.name, "w", format="mp4", options={"movflags": "+faststart"}
            )
        except BaseException:
            self._path.close()
            raise
        try:
            stream = self._container.add_stream(
                "libx264", rate=Fraction(fps).limit_denominator(1001), options=dict(H264_OPTIONS)
            )
            configure(stream.codec_context, width, height)
            if pixel_aspect != 1.0:
                aspect = Fraction(pixel_aspect).limit_denominator(1000)
                stream.codec_context.sample_aspect_ratio = aspect
        except BaseException:
            self._container.close()
            self._path.close()
            raise
        self._stream = stream

    def write(self, bgr: np.ndarray, timestamp: float) -> None:
        frame = self._frames.frame(bgr, round(timestamp * 1000))
        self._container.mux(self._stream.encode(frame))

    def close(self) -> None:
        try:
            self._container.mux(self._stream.encode(None))
        finally:
            self._container.close()
            self._path.close()


class Mp4vEncoder:
    """BGR frames to an MPEG-4 part 2 MP4 (OpenCV) at a constant rate."""

    def __init__(self, path: Path, width: int, height: int, fps: float) -> None:
        fourcc = cv2.VideoWriter.fourcc(*"mp4v")
        with FfmpegPath(path, writing=True) as name:
            self._writer = cv2.VideoWriter(name, fourcc, fps, (width, height))
        if not self._writer.isOpened():
            raise RuntimeError(f"OpenCV cannot write an mp4v video to {path}")

    def write(self, bgr: np.ndarray, timestamp: float) -> None:
        self._writer.write(bgr)

    def close(self) -> None:
        self._writer.release()


def open_encoder(
    path: Path, width: int, height: int, fps: float, pixel_aspect: float = 1.0
) -> _Encoder:
    """H.264 where PyAV can write it, else ``mp4v`` (see the module docstring; OpenCV's writer
    has square pixels only)."""
    reason = h264.h264_unavailable()
    if reason is None:
        return H264Encoder(path, width, height, fps, pixel_aspect)
    log.warning("annotated video falls back to mp4v, which browsers do not play: %s", reason)
    return Mp4vEncoder(path, width, height, fps)


class VideoWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        fps = max(info.fps / info.frame_step, 1.0)
        self._size = (info.width, info.height)
        self._encoder = open_encoder(path, info.width, info.height, fps, info.pixel_aspect)
        self._drawer = TrackDrawer(skeleton=info.skeleton)
        self._zones = None if info.analytics is None else ZoneOverlay(info.analytics)
        self._origin: float | None = None

    def write(
        self,
        frame: TimedFrame,
        message: FrameTracksMessage,
        events: Sequence[AnalyticsEvent] = (),
    ) -> None:
        bgr = cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR)
        if (bgr.shape[1], bgr.shape[0]) != self._size:
            bgr = cv2.resize(bgr, self._size)
        if self._origin is None:  # a job's start: the video is a clip, played from 0
            self._origin = frame.timestamp
        canvas = self._drawer.draw(bgr, message)
        if self._zones is not None:
            self._zones.update(events)
            draw_zones(canvas, self._zones)
        self._encoder.write(canvas, frame.timestamp - self._origin)

    def write_filled(self, message: FrameTracksMessage) -> None:
        pass  # the frame is encoded already; the video shows frames as they were tracked

    def close(self, summary: RunSummary) -> None:
        self._encoder.close()

    def abort(self) -> None:
        try:
            self._encoder.close()
        except Exception:  # the file is discarded; what matters is the first error
            log.debug("closing an aborted annotated video failed", exc_info=True)
