"""MCAP result that opens in Foxglove with the boxes drawn over the video.

Channels (JSON message encoding, JSON Schema schemas):

- ``/camera/image`` - ``foxglove.CompressedVideo``: the tracked frames as H.264, one access unit
  per frame, a key frame every second (:class:`~service.outputs.h264.AccessUnitEncoder`); or,
  with ``images`` "jpeg" (or where PyAV has no H.264 encoder), ``foxglove.CompressedImage``:
  each frame as JPEG, five to ten times the bytes;
- ``/camera/annotations`` - ``foxglove.ImageAnnotations``: per track, the box as a
  ``LINE_LOOP``, the parts as ``POINTS`` (parts the frame placed solid; predicted ones, covered or
  not measured, faded), the skeleton's limbs between two visible parts as a ``LINE_LIST`` and
  the track id as text;
- ``/analytics/events`` - ``vtrack.AnalyticsEvent``: each event of the zones and lines (a
  person crossing a line, entering, leaving or dwelling in a zone), at its frame's time, when
  the job or stream watches any; the zones and lines are drawn in the annotations then, with
  their running counts;
- ``/tracks`` - ``vtrack.FrameTracks``: our own per-frame message
  (:class:`api_schemas.tracks.FrameTracksMessage`) with its JSON Schema; in stream mode
  (:attr:`~service.outputs.base.StreamInfo.live`, a camera's recording) ``vtrack.StreamTracks``,
  the message its tracks key carries (:class:`api_schemas.streams.StreamTracksMessage`).

Every message of a frame has the same log time, publish time and ``timestamp``: the frame's
capture time from the video position (nanoseconds from the start of the video), never the wall
clock, so Foxglove pairs each annotation with its image.
"""

from __future__ import annotations

import json
import logging
import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from pydantic import BaseModel

from api_schemas.analytics import AnalyticsEvent
from api_schemas.streams import StreamTracksMessage
from api_schemas.tracks import FrameTracksMessage
from service import __version__
from service.frames import TimedFrame
from service.outputs import foxglove, h264
from service.outputs.base import RunSummary, StreamInfo, limbs
from service.outputs.h264 import AccessUnitEncoder
from service.outputs.palette import track_colour
from service.outputs.zones import LINE_RGB, ZONE_RGB, ZoneOverlay

log = logging.getLogger(__name__)

IMAGE_TOPIC = "/camera/image"
ANNOTATIONS_TOPIC = "/camera/annotations"
TRACKS_TOPIC = "/tracks"
EVENTS_TOPIC = "/analytics/events"
FRAME_ID = "camera"
JPEG_QUALITY = 85
LABEL_SIZE = 12.0
"""Font size of the id labels, in image pixels."""

CHUNK_BYTES = 1024 * 1024
"""Message bytes per compressed MCAP chunk of a result."""

LIVE_CHUNK_BYTES = 256 * 1024
"""Message bytes per compressed MCAP chunk of a live recording (about 16 frames of 360-px H.264
with their annotations and tracks, 1.6 s at 10 fps): a worker killed mid-recording loses its
open chunk only (:func:`salvage` keeps the rest)."""


def nanoseconds(timestamp: float) -> int:
    return round(timestamp * 1e9)


def image_annotations(
    message: FrameTracksMessage, stamp: int, skeleton: tuple[tuple[str, str], ...] = ()
) -> dict[str, Any]:
    """The ``foxglove.ImageAnnotations`` of one frame; ``skeleton`` the pairs of part names
    drawn as limbs."""
    time = foxglove.time_of(stamp)
    points, texts = [], []
    for track in message.tracks:
        rgb = track_colour(track.track_id)
        b = track.box
        corners = [(b.x, b.y), (b.x + b.w, b.y), (b.x + b.w, b.y + b.h), (b.x, b.y + b.h)]
        points.append(
            {
                "timestamp": time,
                "type": foxglove.LINE_LOOP,
                "points": [{"x": x, "y": y} for x, y in corners],
                "outline_color": foxglove.color(rgb, 0.5 if track.occluded else 1.0),
                "outline_colors": [],
                "fill_color": foxglove.color(rgb, 0.0),
                "thickness": 1.0 if track.occluded else 2.0,
            }
        )
        if track.parts:
            points.append(
                {
                    "timestamp": time,
                    "type": foxglove.POINTS,
                    "points": [{"x": p.x, "y": p.y} for p in track.parts],
                    "outline_color": foxglove.color(rgb),
                    "outline_colors": [
                        foxglove.color(rgb, 1.0 if p.visible and p.measured else 0.3)
                        for p in track.parts
                    ],
                    "fill_color": foxglove.color(rgb),
                    "thickness": 4.0,
                }
            )
        if segments := limbs(track, skeleton):
            points.append(
                {
                    "timestamp": time,
                    "type": foxglove.LINE_LIST,
                    "points": [{"x": x, "y": y} for ends in segments for x, y in ends],
                    "outline_color": foxglove.color(rgb),
                    "outline_colors": [],
                    "fill_color": foxglove.color(rgb, 0.0),
                    "thickness": 1.5,
                }
            )
        texts.append(
            {
                "timestamp": time,
                "position": {"x": b.x, "y": _label_baseline(b.y)},
                "text": str(track.track_id),
                "font_size": LABEL_SIZE,
                "text_color": foxglove.color((255, 255, 255)),
                "background_color": foxglove.color(rgb, 0.8),
            }
        )
    return {"circles": [], "points": points, "texts": texts}


def zone_annotations(annotations: dict[str, Any], overlay: ZoneOverlay, stamp: int) -> None:
    """Add the zones (``LINE_LOOP``), the lines with their 'in' arrows (``LINE_LIST``) and the
    running counts (texts) to a frame's ``foxglove.ImageAnnotations``."""
    time = foxglove.time_of(stamp)
    for polygon in overlay.polygons():
        annotations["points"].append(
            {
                "timestamp": time,
                "type": foxglove.LINE_LOOP,
                "points": [{"x": float(x), "y": float(y)} for x, y in polygon],
                "outline_color": foxglove.color(ZONE_RGB),
                "outline_colors": [],
                "fill_color": foxglove.color(ZONE_RGB, 0.15),
                "thickness": 2.0,
            }
        )
    if segments := overlay.segments():
        annotations["points"].append(
            {
                "timestamp": time,
                "type": foxglove.LINE_LIST,
                "points": [{"x": float(p[0]), "y": float(p[1])} for ends in segments for p in ends],
                "outline_color": foxglove.color(LINE_RGB),
                "outline_colors": [],
                "fill_color": foxglove.color(LINE_RGB, 0.0),
                "thickness": 2.0,
            }
        )
    for label in overlay.labels():
        annotations["texts"].append(
            {
                "timestamp": time,
                "position": {"x": label.x, "y": label.y},
                "text": label.text,
                "font_size": LABEL_SIZE,
                "text_color": foxglove.color((255, 255, 255)),
                "background_color": foxglove.color((0, 0, 0), 0.6),
            }
        )


def _label_baseline(top: float) -> float:
    """Where an id label's bottom edge goes (Foxglove anchors text at its bottom left): just
    above the box, or just inside it where the box starts too near the top of the image for
    the label to show above it."""
    return top - 2.0 if top - 2.0 >= LABEL_SIZE else top + LABEL_SIZE + 2.0


def _encode(document: dict[str, Any]) -> bytes:
    return json.dumps(document, separators=(",", ":")).encode("utf-8")


class McapWriter:
    """The MCAP of a result or, in stream mode (``info.live``), of a camera's recording: its
    ``/tracks`` messages are then :class:`~api_schemas.streams.StreamTracksMessage` and its
    chunks small."""

    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        message_model: type[BaseModel] = StreamTracksMessage if info.live else FrameTracksMessage
        chunk_size = LIVE_CHUNK_BYTES if info.live else CHUNK_BYTES
        self._video = info.mcap_images == "h264"
        if self._video and (reason := h264.h264_unavailable()) is not None:
            log.warning("the MCAP stores JPEG images instead of H.264: %s", reason)
            self._video = False
        self._encoder: AccessUnitEncoder | None = None
        self._file = path.open("wb")
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library=f"visual-tracking {__version__}")
        self._channels = {}
        image_schema = (
            ("foxglove.CompressedVideo", foxglove.COMPRESSED_VIDEO_SCHEMA)
            if self._video
            else ("foxglove.CompressedImage", foxglove.COMPRESSED_IMAGE_SCHEMA)
        )
        for topic, name, schema in (
            (IMAGE_TOPIC, *image_schema),
            (ANNOTATIONS_TOPIC, "foxglove.ImageAnnotations", foxglove.IMAGE_ANNOTATIONS_SCHEMA),
            (
                TRACKS_TOPIC,
                f"vtrack.{message_model.__name__.removesuffix('Message')}",
                message_model.model_json_schema(),
            ),
        ):
            schema_id = self._writer.register_schema(name, "jsonschema", _encode(schema))
            self._channels[topic] = self._writer.register_channel(topic, "json", schema_id)
        self._zones = None if info.analytics is None else ZoneOverlay(info.analytics)
        if self._zones is not None:
            event_schema = _encode(AnalyticsEvent.model_json_schema())
            schema_id = self._writer.register_schema(
                "vtrack.AnalyticsEvent", "jsonschema", event_schema
            )
            self._channels[EVENTS_TOPIC] = self._writer.register_channel(
                EVENTS_TOPIC, "json", schema_id
            )
        self._sequences = dict.fromkeys(self._channels, 0)
        self._info = info

    def write(
        self,
        frame: TimedFrame,
        message: FrameTracksMessage,
        events: Sequence[AnalyticsEvent] = (),
    ) -> None:
        stamp = nanoseconds(frame.timestamp)
        if self._video:
            if self._encoder is None:
                height, width = frame.image.shape[:2]
                self._encoder = AccessUnitEncoder(width, height, "rgb24")
            self._add_video(self._encoder.encode(frame.image, stamp))
        else:
            bgr = cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR)
            ok, jpeg = cv2.imencode(".jpg", bgr, (cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY))
            if not ok:
                raise RuntimeError(f"could not encode frame {frame.index} as JPEG")
            self._add(
                IMAGE_TOPIC, stamp, foxglove.compressed_image(stamp, jpeg.tobytes(), FRAME_ID)
            )
        annotations = image_annotations(message, stamp, self._info.skeleton)
        if self._zones is not None:
            self._zones.update(events)
            zone_annotations(annotations, self._zones, stamp)
            for event in events:
                self._add(EVENTS_TOPIC, stamp, event.model_dump(mode="json"))
        self._add(ANNOTATIONS_TOPIC, stamp, annotations)
        self._add(TRACKS_TOPIC, stamp, message.model_dump(mode="json"))

    def _add_video(self, units: list[tuple[int, bytes]]) -> None:
        for stamp, unit in units:
            self._add(IMAGE_TOPIC, stamp, foxglove.compressed_image(stamp, unit, FRAME_ID, "h264"))

    def _add(self, topic: str, stamp: int, document: dict[str, Any]) -> None:
        self._writer.add_message(
            self._channels[topic],
            log_time=stamp,
            publish_time=stamp,
            data=_encode(document),
            sequence=self._sequences[topic],
        )
        self._sequences[topic] += 1

    def write_filled(self, message: FrameTracksMessage) -> None:
        pass  # the recording shows each frame as it was tracked

    def close(self, summary: RunSummary) -> None:
        if self._encoder is not None:
            self._add_video(self._encoder.flush())
        # The images alone do not give the video's size: H.264 pads odd sides by a pixel.
        video = summary.video
        info = {
            "vtrack_version": __version__,
            "options": self._info.options.model_dump_json(),
            "mode": self._info.mode,
            "width": str(self._info.width),
            "height": str(self._info.height),
            "pixel_aspect_ratio": str(self._info.pixel_aspect),
            "frames_processed": str(summary.frames_processed),
            # a live camera's frames are all tracked; none were announced
            "frames_read": str(summary.frames_processed if video is None else video.frames_read),
            "frame_step": str(self._info.frame_step),
            "part_names": ",".join(self._info.part_names),
            "skeleton": ",".join(f"{a}-{b}" for a, b in self._info.skeleton),
        }
        if video is not None and video.fps:
            info["fps"] = str(video.fps)
        if video is not None and video.start:
            info["start"] = str(video.start)
        if video is not None and video.end is not None:
            info["end"] = str(video.end)
        if self._info.job_id:
            info["job_id"] = self._info.job_id
        self._writer.add_metadata("vtrack", info)
        self._writer.finish()
        self._file.close()

    def abort(self) -> None:
        self._file.close()


def salvage(partial: Path, target: Path) -> int:
    """Write the complete records of an unfinished MCAP file (a writer killed mid-run: no
    summary, the last chunk cut) to a finished file ``target``; return the messages kept.

    Records are read in order until the first one that is cut off; what a killed writer had
    not yet flushed (the open chunk) is lost. ``target`` appears only when it is complete.
    """
    kept = 0
    building = target.with_name(target.name + ".salvage")
    try:
        with partial.open("rb") as source, building.open("wb") as sink:
            writer = Writer(sink, compression=CompressionType.ZSTD)
            writer.start(profile="", library="visual-tracking")
            schemas: dict[int, int] = {}
            channels: dict[int, int] = {}
            try:
                for record in StreamReader(source).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = writer.register_schema(
                            record.name, record.encoding, record.data
                        )
                    elif isinstance(record, Channel) and record.schema_id in schemas:
                        channels[record.id] = writer.register_channel(
                            record.topic, record.message_encoding, schemas[record.schema_id]
                        )
                    elif isinstance(record, Message) and record.channel_id in channels:
                        writer.add_message(
                            channels[record.channel_id],
                            log_time=record.log_time,
                            publish_time=record.publish_time,
                            data=record.data,
                            sequence=record.sequence,
                        )
                        kept += 1
            except (McapError, struct.error):  # what a cut-off record raises
                pass
            writer.add_metadata("vtrack", {"salvaged_from": partial.name})
            writer.finish()
    except BaseException:
        building.unlink(missing_ok=True)
        raise
    os.replace(building, target)
    return kept
