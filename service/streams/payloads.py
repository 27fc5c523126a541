"""Stream payloads: bytes off the wire -> checked numpy frames and detections; tracks -> the
messages a stream publishes.

Everything a camera can get wrong (no attachment, an attachment that is not the schema, a JPEG
that does not decode, raw bytes of the wrong size) raises :class:`PayloadError` with one
sentence saying what; the stream counts it, reports it and goes on with the next frame.
"""

from __future__ import annotations

import json

import av
import cv2
import numpy as np
from pydantic import ValidationError

from api_schemas.streams import (
    MAX_TIMESTAMP,
    FrameAttachment,
    PixelFormat,
    StreamTracksEnded,
    StreamTracksMessage,
    UpstreamDetections,
)
from service.convert import frame_message
from service.frames import MAX_PIXELS, frame_size_problem
from service.outputs.h264 import IDR, nal_unit_types
from tracking.detection.base import Detections
from tracking.detection.external import detections_from_arrays
from tracking.tracks import FrameTracks

JPEG = "image/jpeg"
RAW = "application/octet-stream"
H264 = "video/h264"


MAX_ATTACHMENT_BYTES = 4096
"""A frame's attachment is some 100 bytes of JSON; one this large is no attachment of ours."""

MAX_DETECTIONS_BYTES = 1024**2
"""Some 10,000 detections of one frame: more is a broken or hostile sender, refused before it
is parsed (the frame limit bounds frames; this bounds the other key's messages)."""


class PayloadError(ValueError):
    """A sample that is not a usable frame or detection message."""


def _first_line(error: ValidationError) -> str:
    item = error.errors()[0]
    where = ".".join(str(p) for p in item.get("loc", ())) or "message"
    return f"{where}: {item.get('msg')}"


def parse_attachment(attachment: bytes | None) -> FrameAttachment:
    """The frame's :class:`FrameAttachment`; raises :class:`PayloadError`."""
    if not attachment:
        raise PayloadError("frame without attachment: sequence and timestamp are required")
    if len(attachment) > MAX_ATTACHMENT_BYTES:
        raise PayloadError(
            f"frame attachment of {len(attachment)} bytes is over the limit of "
            f"{MAX_ATTACHMENT_BYTES}: it holds sequence and timestamp (and a raw frame's size)"
        )
    try:
        return FrameAttachment.model_validate_json(attachment)
    except ValidationError as error:
        item = error.errors()[0]
        if item.get("loc") == ("timestamp",) and item.get("type") == "less_than_equal":
            raise PayloadError(
                f"bad frame attachment (timestamp {item.get('input'):.4g} is more than "
                f"{MAX_TIMESTAMP:.0e} s after 1970: timestamps are seconds, not milliseconds)"
            ) from None
        raise PayloadError(f"bad frame attachment ({_first_line(error)})") from None


def decode_frame(payload: bytes, encoding: str, attachment: FrameAttachment) -> np.ndarray:
    """The frame as RGB uint8 ``(H, W, 3)``; raises :class:`PayloadError`.

    ``encoding`` ``image/jpeg`` (any ``image/*`` OpenCV reads) is decoded; anything else is
    raw pixels laid out as the attachment's ``width``, ``height`` and ``format`` say.
    """
    if encoding.startswith("image/"):
        size = image_size(payload)
        if size is not None and size[0] * size[1] > MAX_PIXELS:
            raise PayloadError(
                f"{encoding} frame of {size[0]}x{size[1]} is larger than this service takes"
            )
        buffer = np.frombuffer(payload, dtype=np.uint8)
        bgr = cv2.imdecode(buffer, cv2.IMREAD_COLOR) if buffer.size else None
        if bgr is None:
            raise PayloadError(f"{encoding} payload of {len(payload)} bytes does not decode")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    a = attachment
    if a.width is None or a.height is None or a.format is None:
        raise PayloadError(
            f"raw frame (encoding {encoding or 'none'}) needs width, height and format in its "
            "attachment; or send image/jpeg"
        )
    if a.width * a.height > MAX_PIXELS:
        raise PayloadError(f"raw frame of {a.width}x{a.height} is larger than this service takes")
    expected = a.width * a.height * a.format.channels
    if len(payload) != expected:
        raise PayloadError(
            f"raw {a.format.value} frame of {a.width}x{a.height} needs {expected} bytes, "
            f"got {len(payload)}"
        )
    pixels = np.frombuffer(payload, dtype=np.uint8)
    if a.format is PixelFormat.mono8:
        return cv2.cvtColor(pixels.reshape(a.height, a.width), cv2.COLOR_GRAY2RGB)
    image = pixels.reshape(a.height, a.width, 3)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB) if a.format is PixelFormat.bgr8 else image.copy()


def check_frame_size(image: np.ndarray) -> None:
    """Raise :class:`PayloadError` for a frame too small to be a camera's
    (:data:`~service.frames.MIN_SIDE`): a glitch (a 1x1 placeholder, a broken encoder's output)
    that is dropped, not a change of resolution that would start the tracks over."""
    height, width = image.shape[:2]
    if problem := frame_size_problem(width, height):
        raise PayloadError(problem)


def is_h264(encoding: str) -> bool:
    return encoding.split(";", 1)[0] == H264


class H264Frames:
    """One camera's H.264 stream, decoded unit by unit in arrival order.

    Each sample is one access unit in Annex B form holding exactly one frame, no B-frames (as
    Foxglove's ``CompressedVideo``, and what ``vtrack publish --h264`` sends). Every unit must
    be decoded, dropped frames or not, since the next ones are coded against it. Units before
    the first key frame (IDR) cannot be decoded and are refused; a decoder that joins a stream
    late waits for the camera's next key frame.
    """

    def __init__(self) -> None:
        self._decoder: av.VideoCodecContext | None = None

    def decode(self, unit: bytes) -> np.ndarray:
        """The unit's frame as RGB uint8 ``(H, W, 3)``; raises :class:`PayloadError`."""
        if not unit:  # an empty packet would put the decoder into draining, for good
            raise PayloadError(f"empty {H264} unit")
        if self._decoder is None:
            if IDR not in nal_unit_types(unit):
                raise PayloadError(
                    f"{H264} unit of {len(unit)} bytes before the first key frame (IDR): "
                    "frames are decoded from the camera's next key frame on"
                )
            self._decoder = av.CodecContext.create("h264", "r")
        try:
            pictures = self._decoder.decode(av.Packet(unit))
        except av.FFmpegError as error:
            raise PayloadError(
                f"{H264} unit of {len(unit)} bytes does not decode ({error})"
            ) from None
        if not pictures:
            raise PayloadError(
                f"{H264} unit of {len(unit)} bytes gave no frame: send one frame per unit, "
                "without B-frames"
            )
        picture = pictures[-1]
        if picture.width * picture.height > MAX_PIXELS:
            raise PayloadError(
                f"{H264} frame of {picture.width}x{picture.height} is larger than this service "
                "takes"
            )
        return picture.to_ndarray(format="rgb24")


_JPEG_FRAME_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
"""Start-of-frame markers (baseline, progressive, lossless...; not DHT, JPG, DAC)."""


def image_size(data: bytes) -> tuple[int, int] | None:
    """``(width, height)`` a JPEG or PNG states in its header, read before decoding it (a few
    kilobytes can state gigapixels); ``None`` for other data or a header cut short."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR" and len(data) >= 24:
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if data[:2] != b"\xff\xd8":
        return None
    at = 2
    while at + 9 <= len(data):
        if data[at] != 0xFF:
            return None
        marker = data[at + 1]
        if marker == 0xFF:  # fill byte before a marker
            at += 1
            continue
        if marker in _JPEG_FRAME_MARKERS:
            height = int.from_bytes(data[at + 5 : at + 7], "big")
            return int.from_bytes(data[at + 7 : at + 9], "big"), height
        at += 2 + int.from_bytes(data[at + 2 : at + 4], "big")  # the segment's length
    return None


def parse_detections(payload: bytes) -> UpstreamDetections:
    """An upstream detections message; raises :class:`PayloadError`."""
    if len(payload) > MAX_DETECTIONS_BYTES:
        raise PayloadError(
            f"detections message of {len(payload)} bytes is over the limit of "
            f"{MAX_DETECTIONS_BYTES}"
        )
    try:
        return UpstreamDetections.model_validate_json(payload)
    except ValidationError as error:
        raise PayloadError(f"bad detections message ({_first_line(error)})") from None


def to_detections(message: UpstreamDetections) -> Detections:
    """Upstream detections as the tracker takes them."""
    boxes = [[d.x, d.y, d.w, d.h] for d in message.detections]
    scores = np.array([d.score for d in message.detections])
    return detections_from_arrays(boxes, scores, np.clip(scores, 0.0, 1.0))  # as the schema says


def encode_jpeg(rgb: np.ndarray, quality: int = 90) -> bytes:
    """An RGB frame as JPEG bytes (what a camera gateway publishes)."""
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return data.tobytes()


def frame_attachment(sequence: int, timestamp: float, **raw: object) -> bytes:
    """The attachment bytes of one frame sample."""
    return json.dumps({"sequence": sequence, "timestamp": timestamp, **raw}).encode()


def tracks_message(
    tracks: FrameTracks,
    *,
    frame_index: int,
    camera: str,
    sequence: int,
    latency: float,
    frames_skipped: int,
    detections: str,
) -> StreamTracksMessage:
    """The payload of the ``tracks`` key for one tracked frame: ``tracks`` (their ids as
    published) converted as an upload's are (:func:`~service.convert.frame_message`), with
    what the stream says of the frame; ``frame_index`` counts the frames the worker tracked."""
    frame = frame_message(tracks, frame_index)
    return StreamTracksMessage(
        frame_index=frame_index,
        timestamp=tracks.timestamp,  # as the camera stamped it, not rounded
        tracks=frame.tracks,
        camera=camera,
        sequence=sequence,
        latency=latency,
        frames_skipped=frames_skipped,
        detections=detections,
    )


def ended_message(last: StreamTracksMessage, reason: str) -> StreamTracksEnded:
    """The payload of the ``tracks/ended`` key: the tracks of ``last``, the last message of a
    run, ended for ``reason``."""
    return StreamTracksEnded(
        camera=last.camera,
        reason=reason,
        sequence=last.sequence,
        timestamp=last.timestamp,
        track_ids=[track.track_id for track in last.tracks],
    )
