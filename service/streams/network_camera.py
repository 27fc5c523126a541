"""A network camera as the source of ``vtrack publish``: RTSP, HTTP(S), RTMP, or MPEG-TS over
TCP or UDP, read with PyAV (FFmpeg).

Surveillance cameras and their recorders serve video on such URLs; ``vtrack publish URL`` is
the gateway that puts one on Zenoh. The camera sets the pace, so what it sends is published
as it arrives. H.264 without B-frames is forwarded as the camera encoded it when H.264 is asked
for (no decoding or encoding on the gateway, and the camera's own quality); anything else is
decoded into frames, which the publisher sends as JPEG, raw pixels, or H.264 again. Each frame
is stamped with the time the camera took it, from its presentation time
(:mod:`.capture_clock`), not with the time it happened to arrive.

A camera that cannot be reached at the start is an error, since a wrong URL should fail at
once; one that drops or stalls later is connected to again, waiting longer after each failed
attempt (cameras reboot, networks come back).
"""

from __future__ import annotations

import threading
import time
import urllib.parse
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field

import av
import numpy as np

from service.frames import MAX_PIXELS
from service.outputs.h264 import IDR, SPS, nal_unit_types, picture_count
from service.streams.capture_clock import CaptureClock, Captured

STREAM_SCHEMES = frozenset({"rtsp", "rtsps", "rtmp", "rtmps", "http", "https", "tcp", "udp", "rtp"})
"""URL schemes read as network cameras: the protocols for live video that PyAV's FFmpeg has."""
INPUT_DEFAULTS = {"analyzeduration": "1000000", "fpsprobesize": "0"}
"""FFmpeg studies a stream for up to 5 s, and counts frames to estimate their rate, before it
gives the first one; a second is enough to learn a camera's codec and size (RTSP states them in
its session description), and the gateway needs no rate since the camera sets the pace. What
arrives meanwhile comes out at once, so a short study also means a small burst after each
connection: 0.1-0.8 s to the first frame instead of 2.1-2.8 s, and 1-8 frames at once instead
of 21-28, on the simulated cameras of benchmarks/gateway.py."""
RTSP_DEFAULTS = {"rtsp_transport": "tcp"}
"""RTSP over TCP: FFmpeg's first choice, UDP, loses packets on a busy network and the frames
then decode smeared; recorders use TCP for the same reason."""
WHOLE_FRAME_SCHEMES = frozenset({"tcp", "udp", "http", "https"})
"""Where cameras and encoders send MPEG-TS, whose packets (PES) carry a frame each. FFmpeg's
parser holds every frame back until the next one starts, to find where it ends; for MPEG-TS
with H.264 it is left out (``fflags=+noparse``), so each frame reaches the gateway a frame
interval sooner (100 ms at 10 fps). A stream on such a URL that turns out to be something else
is opened again with the parser."""
NOPARSE = {"fflags": "+noparse"}
SEVERAL_FRAMES = "the stream packs several frames in one packet"
UNTIMED = (
    "the stream's frame times do not keep pace with the clock (made up by FFmpeg?): "
    "stamping frames as they arrive"
)
FIRST_RETRY_SECONDS = 1.0
LAST_RETRY_SECONDS = 30.0
"""Waits between attempts to reach a camera that dropped: doubling from the first to the last."""


B_FRAMES = "the camera's H.264 has B-frames, which a live decoder cannot take unit by unit"


class CameraUnavailable(ConnectionError):
    """A network camera that cannot be reached, sends no video, or broke off; ``reason`` is
    the message without the camera's URL."""

    def __init__(self, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.reason = reason or message


class ReorderedFrames(CameraUnavailable):
    """H.264 forwarded as units turned out to have B-frames (frames out of order)."""


class SeveralFrames(CameraUnavailable):
    """A stream read without FFmpeg's parser turned out to carry several frames in a packet."""


def is_stream_url(source: str) -> bool:
    """Whether ``source`` is a URL of a network camera (``rtsp://...``) rather than a path."""
    scheme, separator, _ = source.partition("://")
    return bool(separator) and scheme.lower() in STREAM_SCHEMES


def redacted(url: str) -> str:
    """``url`` with its password replaced by ``***``: messages and logs must not carry it."""
    parts = urllib.parse.urlsplit(url)
    if parts.password is None:
        return url
    user = parts.username or ""
    host = parts.netloc.rpartition("@")[2]
    return urllib.parse.urlunsplit(parts._replace(netloc=f"{user}:***@{host}"))


@dataclass(frozen=True, slots=True)
class CameraSettings:
    """How to reach a camera.

    Attributes
    ----------
    open_timeout:
        Seconds to wait for the camera to answer and describe its stream.
    read_timeout:
        Seconds without data after which a connected camera counts as lost.
    options:
        FFmpeg options of the input (``rtsp_transport``, ``analyzeduration``...), over
        :data:`INPUT_DEFAULTS` and, for RTSP, :data:`RTSP_DEFAULTS`.
    """

    open_timeout: float = 10.0
    read_timeout: float = 5.0
    options: Mapping[str, str] = field(default_factory=dict)


class CameraConnection:
    """One connection to a camera: its video stream, as frames or as forwarded H.264 units.

    Attributes
    ----------
    forwarding:
        Whether :meth:`items` gives the camera's H.264 access units (Annex B, one frame each,
        starting at a key frame) instead of decoded frames.
    whole_frames:
        Whether the stream's packets are taken as whole frames, without FFmpeg's parser
        (:data:`WHOLE_FRAME_SCHEMES`): MPEG-TS with H.264 on such a URL, unless ``parse`` was
        asked for or the user set ``fflags``.
    description:
        What the camera sends and how it is passed on, for the user.
    """

    def __init__(
        self, url: str, settings: CameraSettings, forward_h264: bool, parse: bool = False
    ) -> None:
        self._url = url
        self._settings = settings
        scheme = url.partition("://")[0].lower()
        defaults = INPUT_DEFAULTS | (RTSP_DEFAULTS if scheme.startswith("rtsp") else {})
        options = defaults | dict(settings.options)
        self.whole_frames = (
            not parse and scheme in WHOLE_FRAME_SCHEMES and "fflags" not in settings.options
        )
        self._container = self._open(options | NOPARSE if self.whole_frames else options)
        self._stream = self._container.streams.video[0]
        context = self._stream.codec_context
        if self.whole_frames and (self._container.format.name, context.name) != ("mpegts", "h264"):
            self._container.close()
            self.whole_frames = False
            self._container = self._open(options)
            self._stream = self._container.streams.video[0]
            context = self._stream.codec_context
        not_forwarded = self._not_forwarded(context) if forward_h264 else None
        self.forwarding = forward_h264 and not_forwarded is None
        rate = self._stream.average_rate
        self.description = context.name  # size and rate when the study found them
        self.description += f" {context.width}x{context.height}" if context.width else ""
        self.description += f" at {float(rate):g} fps" if rate else ""
        if self.forwarding:
            self.description += ", forwarded as the camera encoded it"
        elif not_forwarded:
            self.description += f", encoded again as H.264 ({not_forwarded})"
        # MP4, FLV (RTMP) and Matroska carry H.264 with length prefixes (avcC); the service
        # takes Annex B, which RTSP and MPEG-TS carry already.
        self._to_annex_b = None
        self._parameter_sets = b""
        extradata = context.extradata or b""
        if self.forwarding and extradata[:1] == b"\x01":
            self._to_annex_b = av.bitstream.BitStreamFilterContext("h264_mp4toannexb", self._stream)
        elif self.forwarding:
            self._parameter_sets = extradata

    def _open(self, options: dict[str, str]):
        """The camera's container, opened with FFmpeg ``options``; it has a video stream."""
        timeout = (self._settings.open_timeout, self._settings.read_timeout)
        try:
            container = av.open(self._url, options=options, timeout=timeout)
        except av.FFmpegError as error:
            reason = self._reason(error)
            raise CameraUnavailable(f"cannot open {redacted(self._url)}: {reason}") from None
        # FFmpeg renders text files (its "tty" format) as video: a camera's error page is not.
        if not container.streams.video or container.format.name == "tty":
            container.close()
            raise CameraUnavailable(f"{redacted(self._url)} sends no video")
        return container

    @staticmethod
    def _not_forwarded(context) -> str | None:
        """Why the camera's stream cannot be forwarded as H.264 units, or None."""
        if context.name != "h264":
            return f"the camera sends {context.name}"
        if context.has_b_frames:
            return B_FRAMES
        return None

    def _reason(self, error: av.FFmpegError) -> str:
        if isinstance(error, av.ExitError):  # FFmpeg's interrupt: the timeout ran out
            return f"no data for {self._settings.read_timeout:g} s"
        return error.strerror or type(error).__name__

    def items(self) -> Iterator[tuple[np.ndarray | bytes, float | None]]:
        """RGB frames (or, when :attr:`forwarding`, H.264 access units) until the stream ends,
        each with its presentation time in seconds (``None`` when the stream has none).

        Raises :class:`CameraUnavailable` when it breaks off (an error, or no data for the
        read timeout). Closes the connection at the end.
        """
        try:
            if self.forwarding:
                yield from self._access_units()
            else:
                yield from self._frames()
        except av.FFmpegError as error:
            reason = self._reason(error)
            raise CameraUnavailable(f"{redacted(self._url)}: {reason}", reason) from None
        finally:
            self._container.close()

    def _packets(self) -> Iterator[tuple[av.Packet, int | None]]:
        """The video stream's packets, each with the number of pictures that start in it when
        read without the parser (``None`` otherwise). More than one ends the connection: a
        decoder would drop the others, and forwarding would send them as one unit."""
        for packet in self._container.demux(self._stream):
            pictures = picture_count(bytes(packet)) if self.whole_frames and packet.size else None
            if pictures is not None and pictures > 1:
                raise SeveralFrames(f"{redacted(self._url)}: {SEVERAL_FRAMES}")
            yield packet, pictures

    def _frames(self) -> Iterator[tuple[np.ndarray, float | None]]:
        for packet, _ in self._packets():
            try:
                pictures = packet.decode()  # the last, empty packet flushes the decoder
            except av.InvalidDataError:
                continue  # a damaged packet (lost data): the next key frame repairs the picture
            for picture in pictures:
                # checked before conversion: a camera (or a forged stream) can state
                # 16000x16000 in a few bytes, 0.8 GB once converted
                if picture.width * picture.height > MAX_PIXELS:
                    reason = (
                        f"a frame of {picture.width}x{picture.height} pixels, more than this "
                        f"service takes ({MAX_PIXELS / 1e6:.0f} megapixels, 8192x8192)"
                    )
                    raise CameraUnavailable(f"{redacted(self._url)}: {reason}", reason)
                yield picture.to_ndarray(format="rgb24"), picture.time

    def _access_units(self) -> Iterator[tuple[bytes, float | None]]:
        started, previous, held = False, None, b""
        for packet, pictures in self._packets():
            if packet.size == 0:
                continue
            # A stream joined between key frames may not show its B-frames when it is opened.
            if previous is not None and packet.pts is not None and packet.pts < previous:
                raise ReorderedFrames(f"{redacted(self._url)}: {B_FRAMES}")
            previous = packet.pts if packet.pts is not None else previous
            for unit_packet in self._to_annex_b.filter(packet) if self._to_annex_b else [packet]:
                unit = held + bytes(unit_packet)
                # Without the parser, parameter sets or SEI may come in a packet of their own:
                # they belong to the next frame's unit.
                if pictures == 0:
                    held = unit
                    continue
                held = b""
                types = nal_unit_types(unit)
                if IDR in types:
                    started = True
                    if SPS not in types:  # the parameter sets came in the stream description
                        unit = self._parameter_sets + unit
                if started:  # the service decodes from a key frame on; earlier units are waste
                    yield unit, _seconds(packet)


class NetworkCamera:
    """A camera's stream that goes on across drops: frames (or H.264 units) from every
    connection in turn.

    Creating it connects (raising :class:`CameraUnavailable`). Iterating gives what
    :meth:`CameraConnection.items` gives, as :class:`.Captured` items stamped with their capture
    time (:class:`.CaptureClock`); when the stream ends or breaks off, ``tell`` says so
    and the camera is connected to again, after :data:`FIRST_RETRY_SECONDS`, doubling up to
    :data:`LAST_RETRY_SECONDS` while it cannot be reached. Iteration ends only when ``stop`` is
    set.
    """

    def __init__(
        self,
        url: str,
        settings: CameraSettings | None = None,
        *,
        forward_h264: bool = False,
        tell: Callable[[str], None] = lambda news: None,
        stop: threading.Event | None = None,
    ) -> None:
        self.url = url
        self._settings = settings or CameraSettings()
        self._forward = forward_h264
        self._parse = False
        self._tell = tell
        self._stop = stop or threading.Event()
        self.connection = self._connect()
        self.connections = 1
        self._clock = CaptureClock()

    def _connect(self) -> CameraConnection:
        return CameraConnection(self.url, self._settings, self._forward, self._parse)

    def __iter__(self) -> Iterator[Captured]:
        name = redacted(self.url)
        while True:
            try:
                for item, position in self.connection.items():
                    trusted = self._clock.trusted
                    stamp = self._clock.stamp(position, time.time())
                    if trusted and not self._clock.trusted:
                        self._tell(f"{name}: {UNTIMED}")
                    yield Captured(item, stamp)
                what = "the stream ended"
            except ReorderedFrames:
                self._forward = False
                what = f"{B_FRAMES}: decoding it instead"
            except SeveralFrames:
                self._parse = True
                what = f"{SEVERAL_FRAMES}: reading it with FFmpeg's parser (a frame later)"
            except CameraUnavailable as error:
                what = f"the stream broke off ({error.reason})"
            delay = FIRST_RETRY_SECONDS
            self._tell(f"{name}: {what}; connecting again in {delay:g} s")
            while not self._stop.wait(delay):
                try:
                    self.connection = self._connect()
                    break
                except CameraUnavailable as error:
                    delay = min(2 * delay, LAST_RETRY_SECONDS)
                    self._tell(f"{error}; trying again in {delay:g} s")
            else:
                return
            self.connections += 1
            self._clock.restart()
            self._tell(f"{name}: connected again ({self.connection.description})")


def _seconds(packet: av.Packet) -> float | None:
    """A packet's presentation time in seconds (its decoding time if it has none)."""
    stamp = packet.pts if packet.pts is not None else packet.dts
    if stamp is None or packet.time_base is None:
        return None
    return float(stamp * packet.time_base)
