"""H.264 through PyAV (x264, which PyAV's wheels carry): the annotated MP4's codec and the MCAP's
video channel.

Licence: x264 is GPL-2.0. A deployment that must not ship GPL code installs PyAV built against
an FFmpeg without x264; :func:`h264_unavailable` then says why, and the writers fall back to
``mp4v`` (MP4) and JPEG (MCAP).
"""

from __future__ import annotations

import functools
from fractions import Fraction

import cv2
import numpy as np

H264_OPTIONS = {"preset": "veryfast", "crf": "23"}
"""x264 settings: ``veryfast`` encodes a 360-px frame in about 2 ms, into a third of the bytes
of OpenCV's ``mp4v``; ``crf`` 23 is x264's default quality."""
MILLISECOND = Fraction(1, 1000)
"""Time base of the encoders' frames: presentation times in milliseconds."""
SLICE, IDR = 1, 5
"""NAL unit types of an H.264 frame's slices: other frames', and a key frame's, where decoding
can start."""
SPS, PPS = 7, 8
"""NAL unit types of the sequence and picture parameter sets, which a decoder needs before
the first frame."""


@functools.cache
def h264_unavailable() -> str | None:
    """Why H.264 cannot be written here, or ``None`` when it can."""
    try:
        import av
    except ImportError:
        return "PyAV is not installed"
    try:
        av.codec.Codec("libx264", "w")
    except Exception:  # PyAV raises its own UnknownCodecError
        return "PyAV's FFmpeg has no libx264 encoder"
    return None


def nal_units(unit: bytes) -> list[bytes]:
    """The NAL units of an Annex B byte stream, in order: what follows each 00 00 01 start code,
    without the zero bytes before the next (trailing zeros, a 4-byte start code's first)."""
    return [nal for piece in unit.split(b"\x00\x00\x01")[1:] if (nal := piece.rstrip(b"\x00"))]


def nal_unit_types(unit: bytes) -> list[int]:
    """The NAL unit types of an Annex B byte stream, in order (5: IDR slice, 7: SPS, 8: PPS)."""
    return [nal[0] & 0x1F for nal in nal_units(unit)]


def picture_count(unit: bytes) -> int:
    """How many pictures start in an Annex B byte stream: slices whose ``first_mb_in_slice`` is 0
    (the slice header's first field, Exp-Golomb coded, is then the single bit 1)."""
    slices = (nal for nal in nal_units(unit) if nal[0] & 0x1F in (SLICE, IDR) and len(nal) > 1)
    return sum(nal[1] >> 7 for nal in slices)


def even_sides(image: np.ndarray) -> np.ndarray:
    """``image`` with one replicated row and/or column where a side is odd: 4:2:0 halves the
    chroma planes, so x264 needs even sides (padding keeps every pixel where it was, which
    resampling would not)."""
    rows, cols = image.shape[0] % 2, image.shape[1] % 2
    if not (rows or cols):
        return image
    return cv2.copyMakeBorder(image, 0, rows, 0, cols, cv2.BORDER_REPLICATE)


def configure(context, width: int, height: int) -> None:
    """Set an x264 codec context (PyAV) for frames of ``width`` x ``height``: 4:2:0, sides made
    even as :func:`even_sides` makes them, times in milliseconds."""
    context.width, context.height = width + width % 2, height + height % 2
    context.pix_fmt = "yuv420p"
    context.time_base = MILLISECOND


class FrameStamper:
    """PyAV frames for x264 from images and their times: sides made even, presentation times
    in milliseconds that always increase (frames under a millisecond apart are nudged apart,
    as MP4 and x264 need)."""

    def __init__(self, pixel_format: str) -> None:
        import av

        self._frame_type = av.VideoFrame
        self._pixel_format = pixel_format
        self._last_pts = -1

    def frame(self, image: np.ndarray, milliseconds: int):
        frame = self._frame_type.from_ndarray(even_sides(image), format=self._pixel_format)
        frame.pts = self._last_pts = max(milliseconds, self._last_pts + 1)
        frame.time_base = MILLISECOND
        return frame


class AccessUnitEncoder:
    """Frames to H.264 access units in Annex B form, one per frame, for players that decode
    message by message (Foxglove's ``CompressedVideo``): no B-frames and no lookahead (x264's
    ``zerolatency``), so each frame's unit comes out as it goes in; SPS and PPS before every
    key frame; a key frame at least every ``keyframe_seconds`` of stream time (by the stamps,
    so it holds for any frame rate, known or not), where a player can start after a seek.
    """

    def __init__(
        self, width: int, height: int, pixel_format: str, keyframe_seconds: float = 1.0
    ) -> None:
        import av

        self._frames = FrameStamper(pixel_format)
        self._intra = av.video.frame.PictureType.I
        self._keyframe_ns = round(keyframe_seconds * 1e9)
        self._last_key: int | None = None
        context = av.CodecContext.create("libx264", "w")
        configure(context, width, height)
        context.gop_size = 1000  # a bound only: key frames are forced by time (below)
        context.max_b_frames = 0
        # forced-idr: a forced key frame is an IDR, where decoding can start
        context.options = {**H264_OPTIONS, "tune": "zerolatency", "forced-idr": "1"}
        self._context = context
        self._stamps: dict[int, int] = {}  # pts -> the stamp given with the frame

    def encode(self, image: np.ndarray, stamp: int) -> list[tuple[int, bytes]]:
        """(stamp, access unit) of what the encoder gives back for ``image`` (its own unit: the
        encoder has no delay); ``stamp`` (nanoseconds) comes back with the unit."""
        frame = self._frames.frame(image, stamp // 1_000_000)
        self._stamps[frame.pts] = stamp  # units come back with their frame's pts
        if self._last_key is None or stamp - self._last_key >= self._keyframe_ns:
            frame.pict_type = self._intra
            self._last_key = stamp
        return self._units(frame)

    def flush(self) -> list[tuple[int, bytes]]:
        return self._units(None)

    def _units(self, frame) -> list[tuple[int, bytes]]:
        units = []
        for packet in self._context.encode(frame):
            if packet.pts is None:  # never: each unit comes from a frame, and each frame has one
                raise RuntimeError("the H.264 encoder gave a unit without a pts")
            units.append((self._stamps.pop(packet.pts), bytes(packet)))
        return units
