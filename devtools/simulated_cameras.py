"""Network cameras simulated on loopback, for the tests and benchmarks of ``vtrack publish``
(and for trying it without a camera): an RTSP camera (:class:`RtspCamera`), an MPEG-TS camera
on a TCP port (:class:`TcpCamera`, as an encoder box or ``ffmpeg -f mpegts tcp://...?listen``
serves one) and files over HTTP (:class:`FileServer`).

Each is real network I/O that FFmpeg, inside ``vtrack publish``, reads as it reads a camera.
"""

from __future__ import annotations

import base64
import functools
import http.server
import io
import itertools
import socket
import struct
import threading
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

import av
import numpy as np

from service.outputs.h264 import PPS, SPS, AccessUnitEncoder, nal_units

DELIMITER = 9
"""NAL unit type of an access unit delimiter."""


def h264_video(
    frames: Iterable[np.ndarray], container: str, target=None, fps: int = 10, b_frames: int = 0
) -> bytes:
    """RGB ``frames`` as H.264 in ``container`` (``mpegts``, ``mp4``...), with a key frame every
    second and, as surveillance cameras encode, no B-frames unless ``b_frames``; the bytes, and
    the file ``target`` when given."""
    buffer = io.BytesIO()
    options = {"movflags": "faststart"} if container == "mp4" else {}
    output = av.open(target or buffer, "w", format=container, options=options)
    stream = output.add_stream("libx264", rate=fps)
    stream.pix_fmt = "yuv420p"
    stream.codec_context.options = {"g": str(fps), "bf": str(b_frames)}
    if not b_frames:
        stream.codec_context.options |= {"tune": "zerolatency"}
    frames = list(frames)
    stream.height, stream.width = frames[0].shape[:2]
    for image in frames:
        output.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
    output.mux(stream.encode())
    output.close()
    return Path(target).read_bytes() if target else buffer.getvalue()


def access_units(frames: Sequence[np.ndarray], fps: float = 10.0) -> list[bytes]:
    """RGB ``frames`` as a camera's H.264 access units, ``fps`` frames a second: Annex B, one
    unit per frame, no B-frames, a key frame every second (:class:`AccessUnitEncoder`)."""
    height, width = frames[0].shape[:2]
    encoder = AccessUnitEncoder(width, height, "rgb24")
    period = round(1e9 / fps)
    return [unit for i, image in enumerate(frames) for _, unit in encoder.encode(image, i * period)]


class _Listener:
    """A loopback server at ``url`` (``url_pattern`` with its port) that serves each connection
    on a thread of its own (``_serve(connection, number)``, numbered from 0)."""

    def __init__(self, url_pattern: str) -> None:
        self.connections = 0
        self._closed = threading.Event()
        self._server = socket.create_server(("127.0.0.1", 0))
        self.url = url_pattern.format(port=self._server.getsockname()[1])
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while not self._closed.is_set():
            try:
                connection, _ = self._server.accept()
            except OSError:
                return
            number, self.connections = self.connections, self.connections + 1
            threading.Thread(target=self._serve, args=(connection, number), daemon=True).start()

    def _serve(self, connection: socket.socket, number: int) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Stop answering: connections are refused from now on."""
        self._closed.set()
        # A thread blocked in accept() keeps the port open past close(); shutdown wakes it.
        self._server.shutdown(socket.SHUT_RDWR)
        self._server.close()


class TcpCamera(_Listener):
    """A camera serving an MPEG-TS stream to whoever connects to its port, a frame every
    ``1 / fps`` seconds (all at once when ``fps`` is 0).

    Each connection plays the next entry of ``plan`` (the last one repeats): ``"whole"`` sends
    the stream and hangs up, ``"drop"`` hangs up after three quarters of it, ``"stall"`` sends
    three quarters and then nothing until the camera is closed. ``delays`` (seconds, one per
    frame, cycled) hold frames back after they are taken, as a congested network does; frames
    stay in order, so a delayed frame holds back those behind it. :attr:`taken` lists when the
    latest connection's frames were taken (Unix time), the truth a gateway's stamps are
    measured against.
    """

    VIDEO_PID = 0x100  # FFmpeg's MPEG-TS muxer puts the first stream there

    def __init__(
        self,
        stream: bytes,
        plan: Iterable[str] = ("whole",),
        fps: float = 0,
        delays: Sequence[float] = (0.0,),
    ) -> None:
        self._frames = self.split(stream)
        self._plan = list(plan)
        self._period = 1.0 / fps if fps else 0.0
        self._delays = list(delays)
        self.taken: list[float] = []
        super().__init__("tcp://127.0.0.1:{port}")

    @classmethod
    def split(cls, stream: bytes) -> list[bytes]:
        """The stream cut before each TS packet that starts a video frame (its PES packet)."""
        starts = [
            at
            for at in range(0, len(stream), 188)
            if stream[at + 1] & 0x40
            and (stream[at + 1] & 0x1F) << 8 | stream[at + 2] == cls.VIDEO_PID
        ]
        cuts = [0, *starts[1:], len(stream)]
        return [stream[a:b] for a, b in itertools.pairwise(cuts)]

    def _serve(self, connection: socket.socket, number: int) -> None:
        plan = self._plan[min(number, len(self._plan) - 1)]
        frames = self._frames if plan == "whole" else self._frames[: len(self._frames) * 3 // 4]
        self.taken = taken = []
        start = time.time()
        try:
            for index, frame in enumerate(frames):
                taken.append(start + index * self._period)
                delay = self._delays[index % len(self._delays)]
                time.sleep(max(taken[-1] + delay - time.time(), 0.0))
                connection.sendall(frame)
            if plan == "stall":
                self._closed.wait()
        except OSError:
            pass  # the reader hung up
        finally:
            connection.close()


class FileServer:
    """A folder's files over HTTP on a loopback port (``url(name)``)."""

    def __init__(self, folder: Path) -> None:
        handler = functools.partial(_QuietHandler, directory=str(folder))
        self._server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        threading.Thread(target=self._server.serve_forever, daemon=True).start()

    def url(self, name: str) -> str:
        return f"http://127.0.0.1:{self._server.server_port}/{name}"

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args) -> None:
        pass


class RtspCamera(_Listener):
    """An RTSP camera (RFC 2326) on a loopback port: the protocol of IP cameras, reduced to what
    a client needs to play one H.264 stream over TCP (RTP interleaved in the RTSP connection,
    RFC 6184 packetization).

    Like many cameras it states its parameter sets (SPS, PPS) only in the session description,
    not before each key frame. It sends ``units`` (Annex B access units, one frame each) at
    ``fps`` and hangs up after the last. :attr:`sent` lists when the latest connection's
    frames went out whole (Unix time).
    """

    PAYLOAD_TYPE = 96
    MTU = 1400

    def __init__(self, units: list[bytes], fps: float = 10.0, path: str = "stream1") -> None:
        self._nals = [nal_units(unit) for unit in units]
        sets = {nal[0] & 0x1F: nal for nal in self._nals[0] if nal[0] & 0x1F in (SPS, PPS)}
        self._sprop = ",".join(base64.b64encode(sets[kind]).decode() for kind in (SPS, PPS))
        self._period = 1.0 / fps
        self.sent: list[float] = []
        super().__init__(f"rtsp://127.0.0.1:{{port}}/{path}")

    def _serve(self, connection: socket.socket, number: int) -> None:
        reader = connection.makefile("rb")
        try:
            while (request := self._request(reader)) is not None:
                method, headers = request
                reply = [f"CSeq: {headers.get('cseq', '0')}"]
                body = b""
                if method == "OPTIONS":
                    reply.append("Public: OPTIONS, DESCRIBE, SETUP, PLAY, TEARDOWN")
                elif method == "DESCRIBE":
                    body = self._description().encode()
                    reply += ["Content-Type: application/sdp", f"Content-Base: {self.url}/"]
                elif method == "SETUP":
                    reply += [f"Transport: {headers['transport']}", "Session: 12345678"]
                elif method == "PLAY":
                    reply.append("Session: 12345678")
                head = "RTSP/1.0 200 OK\r\n" + "".join(f"{line}\r\n" for line in reply)
                head += f"Content-Length: {len(body)}\r\n\r\n"
                connection.sendall(head.encode() + body)
                if method == "PLAY":
                    threading.Thread(target=self._play, args=(connection,), daemon=True).start()
        except OSError:
            pass
        finally:
            connection.close()

    @staticmethod
    def _request(reader) -> tuple[str, dict[str, str]] | None:
        """The next request's method and headers, skipping interleaved RTCP from the client."""
        while True:
            first = reader.read(1)
            if not first:
                return None
            if first == b"$":  # an interleaved packet: channel, length, data
                length = int.from_bytes(reader.read(3)[1:], "big")
                reader.read(length)
                continue
            line = (first + reader.readline()).decode().strip()
            if not line:
                continue
            headers = {}
            while header := reader.readline().decode().strip():
                name, _, value = header.partition(":")
                headers[name.strip().lower()] = value.strip()
            return line.split()[0], headers

    def _description(self) -> str:
        return (
            "v=0\r\no=- 0 0 IN IP4 127.0.0.1\r\ns=camera\r\nc=IN IP4 0.0.0.0\r\nt=0 0\r\n"
            f"m=video 0 RTP/AVP {self.PAYLOAD_TYPE}\r\n"
            f"a=rtpmap:{self.PAYLOAD_TYPE} H264/90000\r\n"
            f"a=fmtp:{self.PAYLOAD_TYPE} packetization-mode=1;"
            f"sprop-parameter-sets={self._sprop}\r\n"
            "a=control:track1\r\n"
        )

    def _play(self, connection: socket.socket) -> None:
        sequence = 0
        self.sent = sent = []
        try:
            for index, nals in enumerate(self._nals):
                stamp = index * round(90000 * self._period)
                # Parameter sets went in the description; access unit delimiters are optional.
                slices = [nal for nal in nals if nal[0] & 0x1F not in (SPS, PPS, DELIMITER)]
                packets = [p for nal in slices for p in self._packets(nal)]
                for number, payload in enumerate(packets):
                    last = number == len(packets) - 1  # the marker bit ends the access unit
                    header = struct.pack(
                        "!BBHII",
                        0x80,
                        self.PAYLOAD_TYPE | (0x80 if last else 0),
                        sequence,
                        stamp,
                        0x1234ABCD,
                    )
                    packet = header + payload
                    connection.sendall(b"$\x00" + struct.pack("!H", len(packet)) + packet)
                    sequence = (sequence + 1) & 0xFFFF
                sent.append(time.time())
                time.sleep(self._period)
            connection.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass

    @classmethod
    def _packets(cls, nal: bytes) -> list[bytes]:
        """RTP payloads of one NAL unit: itself, or FU-A fragments when over the MTU."""
        if len(nal) <= cls.MTU:
            return [nal]
        indicator = (nal[0] & 0xE0) | 28
        body = nal[1:]
        pieces = [body[i : i + cls.MTU] for i in range(0, len(body), cls.MTU)]
        return [
            bytes(
                [
                    indicator,
                    (0x80 if i == 0 else 0)
                    | (0x40 if i == len(pieces) - 1 else 0)
                    | (nal[0] & 0x1F),
                ]
            )
            + piece
            for i, piece in enumerate(pieces)
        ]
