"""Reading frames from a video file or an image folder, as RGB numpy arrays."""

from __future__ import annotations

import contextlib
import functools
import itertools
import math
import os
import re
import struct
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import av
import av.logging
import cv2
import numpy as np

from service.ffmpeg_paths import FfmpegPath
from tracking.datasets.mot import (
    MotFormatError,
    read_seqinfo,
    seqinfo_frame_rate,
    seqinfo_whole_number,
)
from tracking.image_files import read_rgb

DEFAULT_FPS = 25.0
"""Frame rate assumed for image folders and videos that declare none."""

_NOT_A_FRAME_RATE = 1000.0
"""A stated rate this high is a millisecond time base, not frames per second."""

MIN_SIDE = 32
"""Fewest pixels a frame's width and height may have, in uploads, folders and streams alike.
The smallest sensors sold as cameras (80x60 thermal cores, 128x96 SQCIF) are above it; below it
a person is a few pixels tall, out of reach of any detector (the default one needs 64 px at its
largest enlargement), and a target a few pixels wide has nothing for a filter to learn."""


MAX_PIXELS = 8192 * 8192
"""Most pixels a frame may have, in uploads and streams alike: above 8K (7680x4320, the most the
detector takes), and 200 MB as RGB. A few kilobytes of H.264 can state 16000x16000 frames,
which would take gigabytes to decode."""

_REFERENCING_FORMATS = frozenset(
    {"concat", "hls", "dash", "imf", "sdp", "rtp", "rtsp", "webm_dash_manifest", "vapoursynth"}
)
"""FFmpeg demuxers whose files are lists or scripts that name other files or addresses: an
upload of one (an ffconcat list named clip.mp4) would make the service read those instead."""


def frame_size_problem(width: int, height: int) -> str | None:
    """Why frames of ``width`` x ``height`` cannot be tracked (:data:`MIN_SIDE`), or None."""
    if min(width, height) >= MIN_SIDE:
        return None
    return (
        f"a frame size of {width}x{height} is too small to track: width and height must be at "
        f"least {MIN_SIDE} pixels"
    )


def is_greyscale(image: np.ndarray) -> bool:
    """Whether an RGB frame is grey: an infrared or monochrome camera's (channels equal but for
    the rounding of a compressed video's neutral chroma)."""
    pixels = image.reshape(-1, 3).astype(np.int16)
    return bool(np.abs(pixels[:, 1:] - pixels[:, :1]).max() <= 2)


IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


class FrameSourceError(ValueError):
    """A path that is not a readable video or image folder.

    Attributes
    ----------
    reason:
        Why a file holds no video, where that can be told (:func:`_undecodable_reason`),
        without the path: for messages to those who sent the file under another name.
    """

    def __init__(self, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class TimedFrame:
    """One decoded frame and where it sits in its video.

    Attributes
    ----------
    index:
        0-based position of the frame in the video (skipped frames count).
    timestamp:
        Presentation time in seconds from the video's first frame (``index / fps`` for a
        constant-rate video).
    image:
        RGB uint8 ``(H, W, 3)``.
    """

    index: int
    timestamp: float
    image: np.ndarray


@dataclass(slots=True)
class ReadProgress:
    """How far :meth:`FrameSource.timed` has read: every frame counts, skipped ones too.

    Attributes
    ----------
    frames:
        Frames read so far.
    end_time:
        Timestamp of the last frame read, in seconds from the first.
    undecodable:
        Indices of the frames that did not decode between frames that did (damaged data);
        reading went on after them.
    reached_end:
        Reading stopped at the ``end`` it was given, before the video's own end.
    on_read:
        Called after each frame read, skipped ones too: progress and cancellation keep going
        through the frames before a ``start``, which are read without being yielded. What it
        raises ends the reading.
    """

    frames: int = 0
    end_time: float = 0.0
    undecodable: list[int] = field(default_factory=list)
    reached_end: bool = False
    on_read: Callable[[], None] | None = None


@dataclass(frozen=True, slots=True)
class FrameSource:
    """Frames of one video or image sequence.

    Attributes
    ----------
    path:
        The video file or image folder.
    frame_count:
        Number of frames: as the container states it, else estimated from its duration and
        frame rate (``count_stated`` false: Matroska and WebM state none).
    fps:
        Frame rate, or ``None`` when unknown (image folders without ``seqinfo.ini``).
    width, height:
        Size of the first frame in pixels.
    count_stated:
        Whether the container states ``frame_count`` (image folders: always).
    duration:
        The video's duration in seconds, ``None`` when the file states none.
    pixel_aspect:
        Width over height of one stored pixel (the container's sample aspect ratio): 12/11
        for PAL D1 recorders (704x576 shown as 4:3), 1 for square pixels. Frames come in
        stored pixels; a player shows them ``pixel_aspect`` times wider.
    lead_frames, lead_seconds:
        Frames before the video's first keyframe, and how long they last: a clip cut from a
        longer recording without its keyframe starts with pictures that reference ones it
        lacks, and decoding starts at the first keyframe. The frames read are numbered and
        timed from there.
    notes:
        What an image folder's layout leaves out or contradicts (images missing from its
        numbering, a ``seqinfo.ini`` whose length or rate does not fit), in sentences for the
        user; empty for videos.
    """

    path: Path
    frame_count: int
    fps: float | None
    _images: tuple[Path, ...] = ()
    _indices: tuple[int, ...] = ()  # each image's frame index (numbered names keep gaps)
    width: int = 0
    height: int = 0
    count_stated: bool = True
    duration: float | None = None
    pixel_aspect: float = 1.0
    lead_frames: int = 0
    lead_seconds: float = 0.0
    notes: tuple[str, ...] = ()

    def __iter__(self) -> Iterator[np.ndarray]:
        """RGB uint8 frames ``(H, W, 3)``, in order."""
        if self._images:
            for image_path in self._images:
                yield read_image(image_path)
            return
        for frame in self.timed():
            yield frame.image

    @property
    def timing_fps(self) -> float:
        """The frame rate that turns frame indices into timestamps."""
        return self.fps if self.fps and self.fps > 0 else DEFAULT_FPS

    @property
    def length(self) -> float | None:
        """Seconds from the first frame read to the video's end (its duration, else its frame
        count over its rate), as frame timestamps count them; ``None`` when neither is known."""
        if self.duration is not None:
            return max(self.duration - self.lead_seconds, 0.0)
        if self.frame_count and self.count_stated:
            return (self.frame_count - self.lead_frames) / self.timing_fps
        return None

    def frames_until(self, end: float | None) -> int:
        """About how many frames :meth:`timed` reads to reach ``end`` seconds (all without
        one): a progress bar's total; 0 when the video's count is not known."""
        frames = math.inf if end is None else end * self.timing_fps  # an end of 1e308 s: inf
        return self.frame_count if frames >= self.frame_count else math.ceil(frames)

    def start_problem(self, start: float, option: str = "start") -> str | None:
        """Why no frame is at or after ``start`` seconds, for the user, who gave it as
        ``option``; ``None`` when one is (or may be: a video that states neither duration nor
        frame count).

        A video's last frame shows one frame period before its end: a start between the two
        would be accepted and then find nothing to track.
        """
        if start <= 0:
            return None
        if self._images:
            if self.image_range(start):
                return None
            last = self._indices[-1] / self.timing_fps
            return f"no frame is at or after {option} {start:g} s: the last is at {last:.2f} s"
        length = self.length
        if length is None:
            return None
        if start >= length:
            return f"{option} {start:g} s is not within the video, which lasts {length:.2f} s"
        last = length - 1 / self.timing_fps
        if start > last + 1e-3:  # containers round their durations to the millisecond
            return (
                f"{option} {start:g} s is after the video's last frame, at {last:.2f} s (the "
                f"video lasts {length:.2f} s)"
            )
        return None

    def image_range(self, start: float = 0.0, end: float | None = None) -> range:
        """The indices of an image folder's frames from ``start`` seconds until ``end``
        (``range(0)`` for a video, whose frames' times are known only as they are read)."""
        times = np.asarray(self._indices, dtype=float) / self.timing_fps
        first = int(np.searchsorted(times, start))  # the first at or after start
        stop = len(times) if end is None else int(np.searchsorted(times, end))
        return range(first, max(first, stop))

    def timed(
        self,
        step: int = 1,
        read: ReadProgress | None = None,
        start: float = 0.0,
        end: float | None = None,
    ) -> Iterator[TimedFrame]:
        """Every ``step``-th frame from ``start`` seconds until ``end``, with its index and
        timestamp; ``read``, when given, follows every frame read, skipped ones included (a
        video's length is known only at its end).

        A video frame's timestamp is its presentation time in the container, so the frames of
        a variable-frame-rate video (phones, recorders that drop frames) keep their real
        spacing; where the container gives none that advances, the previous frame's plus
        ``1 / fps`` (:class:`_PresentationClock`). Image folders: ``index / fps``. The first
        frame yielded is the first at or after ``start``, and the step counts from it; frames
        before it and skipped ones are decoded, not converted to RGB (a video cannot be sought
        to a frame exactly, so they are read); reading stops at the first frame at or after
        ``end`` (``read.reached_end``). A frame that does not decode is passed over (its index
        stays its own, and ``read.undecodable`` lists it); a truncated file ends where its data
        does.

        Raises
        ------
        FrameSourceError
            At the first frame over :data:`MAX_PIXELS` (:meth:`_size_problem`), before it is
            converted.
        """
        if step < 1:
            raise ValueError(f"step must be >= 1, got {step}")
        fps = self.timing_fps
        read = read if read is not None else ReadProgress()
        if self._images:
            positions = self.image_range(start, end)
            for position in positions[::step]:
                index = self._indices[position]
                read.frames, read.end_time = index + 1, index / fps
                if read.on_read is not None:
                    read.on_read()
                yield TimedFrame(index, index / fps, read_image(self._images[position]))
            last = self._indices[positions.stop - 1] if positions.stop else -1
            read.frames, read.end_time = last + 1, last / fps
            read.reached_end = positions.stop < len(self._images)
            return
        with _ffmpeg_path(self.path) as name, av.open(name) as container:
            video = container.streams.video[0]
            video.thread_type = "AUTO"  # frame threads as well as slice threads, as OpenCV has
            times = _presentation_times(container, video)
            index, failed, first, clock = 0, 0, None, _PresentationClock(fps)
            for picture in _pictures(container, video):
                if picture is None:
                    failed += 1
                    continue
                if failed:  # frames lost between two that decoded
                    read.undecodable.extend(range(index, index + failed))
                    index, failed = index + failed, 0
                if problem := self._size_problem(picture, index):
                    raise FrameSourceError(problem)
                seconds = clock.time_of(times(picture))
                if end is not None and seconds >= end:
                    read.reached_end = True
                    break
                read.frames, read.end_time = index + 1, seconds
                if read.on_read is not None:
                    read.on_read()
                if seconds >= start and first is None:
                    first = index
                if first is not None and (index - first) % step == 0:
                    yield TimedFrame(index, seconds, self._upright_rgb(picture))
                index += 1

    def _size_problem(self, picture: av.VideoFrame, index: int) -> str | None:
        """Why a decoded frame must not be converted (:data:`MAX_PIXELS`), or None.

        The headers and the first frame were checked when the video was opened; a stream may
        change its size at any keyframe (an H.264 SPS, each JPEG of an MJPEG stream), and a
        16000x16000 picture in the middle takes 0.4 GB and a second to decode, and more to
        scale, again for every such frame. The reading stops at the first, before it is
        converted: decoding that one is all it cost (FFmpeg decodes none over 268 megapixels).
        """
        if picture.width * picture.height <= MAX_PIXELS:
            return None
        return (
            f"frame {index} of {self.path} (counting from 0) is {picture.width}x{picture.height} "
            f"pixels, more than this service takes ({MAX_PIXELS / 1e6:.0f} megapixels, "
            f"8192x8192): the video changes its frame size after its start "
            f"({self.width}x{self.height}); send a video whose frames all keep that size"
        )

    def _upright_rgb(self, picture: av.VideoFrame) -> np.ndarray:
        """A decoded frame as RGB ``(height, width, 3)`` in the video's size, upright.

        Turned as the stream's display matrix says (a phone held upright stores its pictures
        turned), as a player shows them. A frame whose size differs from the first's (a stream
        that changes its size, within :data:`MAX_PIXELS`) is scaled to it in the same
        conversion: the trackers and writers take one frame size per video.
        """
        turns = round(picture.rotation / 90) % 4  # quarter turns, counterclockwise
        stored = (self.height, self.width) if turns % 2 else (self.width, self.height)
        if all(stored) and (picture.width, picture.height) != stored:
            picture = picture.reformat(*stored)
        image = picture.to_ndarray(format="rgb24")
        return np.ascontiguousarray(np.rot90(image, turns)) if turns else image


def _pictures(
    container: av.container.InputContainer, video: av.VideoStream
) -> Iterator[av.VideoFrame | None]:
    """The decoded frames of ``video``, in presentation order, with None for each packet that
    did not decode (damaged data): a frame lost there."""
    _log_ffmpeg_as_opencv()
    for packet in container.demux(video):
        try:
            pictures = packet.decode()
        except av.FFmpegError:
            yield None
            continue
        yield from pictures


@functools.cache
def _log_ffmpeg_as_opencv() -> None:
    """Let PyAV's FFmpeg, which decodes the frames, say what OpenCV's says, which reads the
    first: at the level of ``OPENCV_FFMPEG_LOGLEVEL`` (:func:`service.logs.quiet_ffmpeg` sets
    it from the service's level: errors at debug, nothing below), to standard error through
    FFmpeg's own callback (PyAV's, into Python's logging, takes locks in the decoder's
    threads). Without the variable, or at a negative level, PyAV keeps FFmpeg quiet."""
    level = os.environ.get("OPENCV_FFMPEG_LOGLEVEL", "").strip()
    if level.isdigit():
        av.logging.set_level(int(level))
        av.logging.restore_default_callback()


def _presentation_times(
    container: av.container.InputContainer, video: av.VideoStream
) -> Callable[[av.VideoFrame], float]:
    """How to read a decoded frame's presentation time, in seconds from the stream's start;
    NaN where the file has none (:class:`_PresentationClock` then counts frame periods).

    An elementary stream (a raw ``.h264``) has no times: FFmpeg makes them up at 25 per
    second. AVI stores one time per frame in decoding order, none for presentation: FFmpeg's
    guesses are out of order once B-frames are reordered, and the decoding times, in order,
    are the presentation times shifted by the reorder delay (as OpenCV read them).
    """
    flags = av.format.Flags(container.format.flags)
    if av.format.Flags.no_timestamps in flags:
        return lambda picture: math.nan
    base = float(video.time_base) if video.time_base else 0.0
    origin = video.start_time or 0
    use_dts = "avi" in container.format.name.split(",")

    def seconds(picture: av.VideoFrame) -> float:
        stamp = picture.dts if use_dts or picture.pts is None else picture.pts
        return math.nan if stamp is None or not base else (stamp - origin) * base

    return seconds


class _PresentationClock:
    """Timestamps of successive video frames from their presentation times.

    OpenCV reports the presentation time of the frame just read (``CAP_PROP_POS_MSEC``).
    The first frame is time 0: containers may start later (an H.264 AVI with B-frames puts
    its first frame at two frame periods). A time that is missing, or not after the previous
    frame's (damaged timestamps), gives way to the previous one plus ``1 / fps``, so time
    never stands still or runs backwards.
    """

    def __init__(self, fps: float) -> None:
        self._period = 1.0 / fps
        self._origin: float | None = None
        self._previous: float | None = None

    def time_of(self, presentation: float) -> float:
        valid = math.isfinite(presentation)
        if self._origin is None:
            self._origin = presentation if valid else 0.0
            self._previous = 0.0
            return 0.0
        seconds = presentation - self._origin if valid else -math.inf
        assert self._previous is not None
        if not seconds > self._previous:
            seconds = self._previous + self._period
        self._previous = seconds
        return round(seconds, 6)  # microseconds: drops the float noise of the subtraction


def capture_frames(capture: cv2.VideoCapture) -> Iterator[np.ndarray]:
    """Every frame an OpenCV capture (a file, a camera) gives, as RGB; releases it at the end."""
    try:
        while True:
            ok, bgr = capture.read()
            if not ok:
                return
            yield cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    finally:
        capture.release()


def read_image(path: Path) -> np.ndarray:
    """One image file as RGB uint8; a clear error if it cannot be decoded."""
    rgb = read_rgb(path)
    if rgb is None:
        raise FrameSourceError(f"cannot decode image {path}")
    return rgb


def _ffmpeg_path(path: Path) -> FfmpegPath:
    """:class:`FfmpegPath` of a file to read; a :class:`FrameSourceError` if it cannot be
    opened."""
    try:
        return FfmpegPath(path)
    except OSError as error:
        raise FrameSourceError(f"cannot read {path}: {error.strerror}") from None


def open_frames(path: str | Path, fps: float | None = None) -> FrameSource:
    """Open a video file, a folder of images, an OTB sequence folder (its ``img/``) or a
    MOTChallenge one (its ``img1/``, at the frame rate of its ``seqinfo.ini``).

    ``fps`` is the frame rate of a folder's images (over its ``seqinfo.ini``'s): a video's
    frames carry their own times.

    Raises
    ------
    FrameSourceError
        If the path does not exist, holds no images, or is not a decodable video, or ``fps``
        is given for a video.
    """
    path = Path(path)
    if not path.exists():
        raise FrameSourceError(f"no such file or folder: {path}")
    if fps is not None and not path.is_dir():
        raise FrameSourceError(
            f"a frame rate is for a folder of images; the frames of the video {path} carry "
            "their own times"
        )
    if path.is_dir():
        return _open_folder(path, fps)
    facts = _container_facts(path)  # from the headers: before OpenCV decodes anything
    if reason := facts.refusal:
        raise FrameSourceError(f"{path} is not a video this service takes: {reason}", reason)
    with _ffmpeg_path(path) as name:
        capture = cv2.VideoCapture(name)
    try:
        ok, first = capture.read() if capture.isOpened() else (False, None)
        if not ok or first is None:
            reason = _undecodable_reason(path)
            raise FrameSourceError(
                f"{path} is not a video OpenCV can decode" + (f": {reason}" if reason else ""),
                reason,
            )
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        fps = float(capture.get(cv2.CAP_PROP_FPS)) or None
    finally:
        capture.release()
    if fps is not None and fps >= _NOT_A_FRAME_RATE:
        fps = None  # the time base stated as a rate: WebM recorded in browsers says 1000
    height, width = first.shape[:2]
    if facts.untimed:
        fps = facts.header_rate  # OpenCV reports FFmpeg's default 25 whatever the stream says
    if not facts.count_stated and facts.duration:  # OpenCV's estimate spans the container
        count = round(facts.duration * (fps or DEFAULT_FPS))
    lead_seconds = facts.lead_seconds or facts.lead_frames / (fps or DEFAULT_FPS)  # untimed
    return FrameSource(
        path,
        max(count, 0),
        fps,
        width=width,
        height=height,
        count_stated=facts.count_stated,
        duration=facts.duration,
        pixel_aspect=facts.pixel_aspect,
        lead_frames=facts.lead_frames,
        lead_seconds=lead_seconds,
    )


def _undecodable_reason(path: Path) -> str | None:
    """Why a file whose first frame does not decode holds no video, where that can be told:
    no video track, or an MP4 without its index; ``None`` otherwise."""
    with contextlib.suppress(OSError):  # unreadable: OpenCV's failure says enough
        if _mp4_without_index(path):
            return (
                "it is an MP4/MOV file without its index (no 'moov' box), as a recording is "
                "when the phone or camera stopped before finishing the file"
            )
    try:
        with _ffmpeg_path(path) as name, av.open(name) as container:
            if not container.streams.video:
                kinds = ", ".join(sorted({stream.type for stream in container.streams}))
                return f"it holds no video track (its tracks: {kinds or 'none'})"
    except av.FFmpegError:
        pass
    return None


def _mp4_without_index(path: Path) -> bool:
    """Whether ``path`` is an ISO media file (MP4, MOV) whose top-level boxes have no
    ``moov``, the index of its samples, which writers add when they finish the file."""
    with path.open("rb") as file:
        if file.read(8)[4:8] != b"ftyp":
            return False
        offset = 0
        while True:
            file.seek(offset)
            header = file.read(16)
            if len(header) < 8:
                return True
            size, kind = struct.unpack(">I4s", header[:8])
            if kind == b"moov":
                return False
            if size == 1 and len(header) == 16:  # a 64-bit size follows
                size = struct.unpack(">Q", header[8:])[0]
            if size < 8:  # 0: the box runs to the end of the file
                return True
            offset += size


@dataclass(frozen=True, slots=True)
class _ContainerFacts:
    """What the container says of its video beyond OpenCV's reading.

    Attributes
    ----------
    count_stated:
        Whether it states the video's frame count. OpenCV reports a count either way,
        estimating ``duration x rate`` where the container states none; that estimate is no
        promise (a variable-rate video holds fewer frames), so a video read to its end is
        judged truncated by the duration instead.
    duration:
        The video's duration in seconds, ``None`` when neither the video stream nor the
        container tells it.
    untimed:
        Whether the video is an elementary stream without timestamps (a raw ``.h264``,
        ``.h265`` or ``.m4v`` export).
    header_rate:
        The frame rate the codec's own headers state (H.264's VUI timing), ``None`` if none.
    pixel_aspect:
        The video's sample aspect ratio (1 where it states none).
    lead_frames, lead_seconds:
        As :class:`FrameSource`'s (:func:`_lead_before_keyframe`).
    refusal:
        Why the file must not be decoded at all (:func:`_refusal`); the other facts are then
        the defaults.
    """

    count_stated: bool = True
    duration: float | None = None
    untimed: bool = False
    header_rate: float | None = None
    pixel_aspect: float = 1.0
    lead_frames: int = 0
    lead_seconds: float = 0.0
    refusal: str | None = None


def _container_facts(path: Path) -> _ContainerFacts:
    """What the container's headers say; the defaults where FFmpeg cannot read it (OpenCV's
    decoder then has its say)."""
    try:
        with _ffmpeg_path(path) as name, av.open(name) as container:
            if refusal := _refusal(container):
                return _ContainerFacts(refusal=refusal)
            video = container.streams.video[0]
            header_rate = video.codec_context.framerate
            sample_aspect = video.sample_aspect_ratio  # None, or 0/1, when not stated
            return _ContainerFacts(
                video.frames > 0,
                _video_duration(container, video),
                av.format.Flags.no_timestamps in av.format.Flags(container.format.flags),
                float(header_rate) if header_rate else None,
                float(sample_aspect) if sample_aspect else 1.0,
                *_lead_before_keyframe(container, video),
            )
    except (av.FFmpegError, IndexError):  # OpenCV decodes it: keep its count as stated
        return _ContainerFacts()


def _refusal(container: av.container.InputContainer) -> str | None:
    """Why a file must not be decoded, from its headers alone (:data:`MAX_PIXELS`,
    :data:`_REFERENCING_FORMATS`); ``None`` when nothing stands against it."""
    demuxer = container.format.name
    if set(demuxer.split(",")) & _REFERENCING_FORMATS:
        return (
            f"it is an FFmpeg {demuxer} file, which names other files or addresses to read: "
            "send the video itself"
        )
    for video in container.streams.video:
        width, height = video.codec_context.width, video.codec_context.height
        if width * height > MAX_PIXELS:
            return (
                f"its frames of {width}x{height} pixels are more than this service takes "
                f"({MAX_PIXELS / 1e6:.0f} megapixels, 8192x8192)"
            )
    return None


_KEYFRAME_SEARCH = 1000
"""Packets searched for a video's first keyframe; beyond, its start is taken as whole."""


def _lead_before_keyframe(
    container: av.container.InputContainer, video: av.VideoStream
) -> tuple[int, float]:
    """The packets before ``video``'s first keyframe and their duration in seconds (from the
    first packet's time to the keyframe's); ``(0, 0.0)`` when the first packet is a keyframe,
    or no keyframe is flagged in the first :data:`_KEYFRAME_SEARCH` packets (nothing to tell).
    """
    first_time = None
    for count, packet in enumerate(container.demux(video)):
        if count >= _KEYFRAME_SEARCH:
            break
        if packet.size == 0:  # the demuxer's flush packet
            continue
        time = packet.pts if packet.pts is not None else packet.dts
        if first_time is None:
            first_time = time
        if packet.is_keyframe:
            if count == 0 or time is None or first_time is None or video.time_base is None:
                return count, 0.0
            return count, float((time - first_time) * video.time_base)
    return 0, 0.0


_MATROSKA_DURATION = re.compile(r"^(\d+):(\d{2}):(\d{2}(?:\.\d+)?)$")


def _video_duration(container: av.container.InputContainer, video: av.VideoStream) -> float | None:
    """The duration of the video stream: its own, else the per-track ``DURATION`` tag that
    Matroska and WebM writers add, else the container's if the video is its only stream;
    from the video's first frame.

    A container's duration spans all its streams: with an audio track that runs on after the
    last picture (common in recordings), it would make a complete video look truncated.
    """
    if video.duration and video.time_base:
        return float(video.duration * video.time_base)
    if match := _MATROSKA_DURATION.match(video.metadata.get("DURATION", "")):
        hours, minutes, seconds = match.groups()
        end = int(hours) * 3600 + int(minutes) * 60 + float(seconds)
    elif len(container.streams) == 1 and container.duration:
        end = container.duration / av.time_base
    else:
        return None
    # FFmpeg's Matroska writer states when the track ends, not how long it lasts: a file cut
    # with -copyts or a recorder's later segment starts past 0 (MP4's duration is a length)
    if "matroska" in container.format.name and video.start_time and video.time_base:
        start = float(video.start_time * video.time_base)
        if 0 < start < end:
            return end - start
    return end


def _open_folder(path: Path, fps: float | None) -> FrameSource:
    """The images of a folder, an OTB sequence (``img/``) or a MOTChallenge one (the
    ``imDir`` of its ``seqinfo.ini``, else ``img1/``), in the order of their names' numbers."""
    info, ini = _seqinfo_beside(path)
    named = [info["imDir"]] if info and info.get("imDir") else []
    folder = next((path / name for name in (*named, "img", "img1") if (path / name).is_dir()), path)
    images = tuple(
        sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES), key=_natural)
    )
    if not images:
        raise FrameSourceError(f"no image files ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    height, width = read_image(images[0]).shape[:2]
    # a MOTChallenge frame is its file's number (000001.jpg is frame 1); other folders' names
    # follow no rule (times in milliseconds, every fifth frame...): their images are counted
    indices = _mot_frame_indices(images) if info else tuple(range(len(images)))
    notes = _missing_images(images, indices, folder)
    rate = length = None
    # a malformed entry is told, not fatal: the images can be tracked all the same
    if info and ini is not None:  # (a file read comes with its path)
        try:
            rate = seqinfo_frame_rate(ini, info)
        except MotFormatError as error:
            notes.append(str(error))
        try:
            length = seqinfo_whole_number(ini, info, "seqLength")
        except MotFormatError as error:
            notes.append(str(error))
    fps = fps or rate
    if length is not None and length != indices[-1] + 1:
        notes.append(
            f"{ini} states seqLength {length}, but the images of {folder} end at frame "
            f"{indices[-1] + 1}: the frames there were tracked"
        )
    return FrameSource(
        path,
        indices[-1] + 1,
        fps,
        images,
        indices,
        width=width,
        height=height,
        notes=tuple(notes),
    )


def _seqinfo_beside(path: Path) -> tuple[Mapping[str, str], Path | None]:
    """The ``[Sequence]`` of the ``seqinfo.ini`` in ``path`` or above it (``path`` may be a
    sequence's ``img1/``), with the file's path; ``({}, None)`` when there is none, or it
    cannot be read (then the folder is read as any image folder)."""
    for sequence in (path, path.parent):
        try:
            info = read_seqinfo(sequence)
        except MotFormatError:
            return {}, None
        if info:
            return info, sequence / "seqinfo.ini"
    return {}, None


def _natural(path: Path) -> tuple[tuple[int, int | str], ...]:
    """Sort key that puts ``img2`` before ``img10``, as file browsers do."""
    return tuple(
        (0, int(part)) if part.isdigit() else (1, part)
        for part in re.split(r"(\d+)", path.name)
        if part
    )


def _mot_frame_indices(images: tuple[Path, ...]) -> tuple[int, ...]:
    """Each image's 0-based frame index in a MOTChallenge sequence: its name's number less 1,
    so a missing image leaves its frame's gap (as a frame of a video that does not decode
    does) and the frames keep the numbers of gt.txt and det.txt; the images' positions when
    the names do not all carry increasing numbers from 1."""
    found = [re.fullmatch(r"\D*(\d+)", p.stem) for p in images]
    numbers = [int(m.group(1)) for m in found if m]
    if len(numbers) < len(images) or numbers[0] < 1:
        return tuple(range(len(images)))
    if any(b <= a for a, b in itertools.pairwise(numbers)):
        return tuple(range(len(images)))
    return tuple(n - 1 for n in numbers)


def _missing_images(images: tuple[Path, ...], indices: tuple[int, ...], folder: Path) -> list[str]:
    """A note naming the frames a numbered folder has no image for (an empty list if none)."""
    missing = indices[-1] + 1 - len(images)
    if not missing:
        return []
    # (first, last) missing frame, counted from 1, between each two images that are not adjacent
    gaps = [(a + 2, b) for a, b in itertools.pairwise((-1, *indices)) if b > a + 1]
    ranges = ", ".join(
        str(first) if first == last else f"{first}-{last}" for first, last in gaps[:3]
    )
    more = ", ..." if len(gaps) > 3 else ""
    return [
        f"{folder} has no image for {missing} of its frames ({ranges}{more}, counted from 1): "
        "they are left out, and the other frames keep their files' numbers"
    ]
