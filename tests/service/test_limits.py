"""Limits on what a video or a client can make the service hold (issue 78): every frame's size,
request headers and bodies that stall, the number of connections; upload file names without
control characters; no temporary folder left in the system's. Real video files, real servers
on loopback, raw sockets; every wait has a deadline."""

from __future__ import annotations

import fractions
import json
import signal
import socket
import time
from pathlib import Path

import av
import numpy as np
import pytest

from devtools.testing import Server, wait_for
from service import frames
from service.frames import FrameSource, FrameSourceError, open_frames
from service.uploads import _client_filename
from tests.service.conftest import wait_for_state

pytestmark = pytest.mark.slow

OVER = (8208, 8192)
"""A frame size just over the 8192x8192 limit (67.2 against 67.1 megapixels): 0.2 s to decode."""

SINGLE = {
    "mode": "single_target",
    "first_box": {"x": 16, "y": 12, "w": 24, "h": 20},
    "preset": "mosse_gray",
    "formats": ["json"],
}
"""Job options that read every frame and track next to nothing: a job in a fraction of a second."""


def write_mjpeg(path: Path, sizes: list[tuple[int, int]]) -> Path:
    """An MJPEG video whose frame ``i`` has ``sizes[i]`` (width, height) and the grey level
    ``20 + 30 i``: each frame a JPEG of its own size, the container stating the first's.
    The container is the path's (AVI, Matroska)."""
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mjpeg", rate=10)
        stream.width, stream.height = sizes[0]
        stream.pix_fmt = "yuvj420p"
        for index, (width, height) in enumerate(sizes):
            encoder = av.CodecContext.create("mjpeg", "w")
            encoder.width, encoder.height, encoder.pix_fmt = width, height, "yuvj420p"
            encoder.time_base = fractions.Fraction(1, 10)
            image = np.full((height, width, 3), 20 + 30 * index, np.uint8)
            frame = av.VideoFrame.from_ndarray(image, format="rgb24").reformat(format="yuvj420p")
            frame.pts = index
            for packet in [*encoder.encode(frame), *encoder.encode(None)]:
                packet.stream = stream
                packet.pts = packet.dts = index
                packet.time_base = fractions.Fraction(1, 10)
                container.mux(packet)
    return path


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("limits")
    small = [(64, 48)] * 3
    return {
        # one frame over the limit in the middle of a 64x48 video
        "avi": write_mjpeg(folder / "oversized.avi", [*small, OVER, *small]),
        "mkv": write_mjpeg(folder / "oversized.mkv", [*small, OVER, *small]),
        # a size change within the limit
        "resized": write_mjpeg(folder / "resized.avi", [(64, 48)] * 2 + [(128, 96)] * 2),
        "plain": write_mjpeg(folder / "plain.avi", [(64, 48)] * 6),
    }


# -- every frame's size ------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["avi", "mkv"])
def test_a_frame_over_the_limit_mid_video_stops_the_reading_before_it_is_converted(
    videos, monkeypatch, kind
):
    # before: the header and the first frame were checked, and a 16000x16000 frame in the
    # middle was decoded and converted (0.4 GB and a second each, for every such frame)
    converted = []
    upright_rgb = FrameSource._upright_rgb

    def recording(self, picture):
        converted.append((picture.width, picture.height))
        return upright_rgb(self, picture)

    monkeypatch.setattr(FrameSource, "_upright_rgb", recording)
    source = open_frames(videos[kind])
    assert (source.width, source.height) == (64, 48)  # what the container states
    read = frames.ReadProgress()
    yielded = []
    with pytest.raises(FrameSourceError) as refused:
        for frame in source.timed(read=read):
            yielded.append(frame.index)
    assert yielded == [0, 1, 2] and converted == [(64, 48)] * 3
    assert f"frame 3 of {videos[kind]} (counting from 0) is 8208x8192 pixels" in str(refused.value)
    assert "8192x8192" in str(refused.value)


def test_a_size_change_within_the_limit_is_scaled_to_the_first_frames_size(videos):
    # the trackers and writers take one size per video: frames of another are scaled to it
    images = [frame.image for frame in open_frames(videos["resized"]).timed()]
    assert [image.shape for image in images] == [(48, 64, 3)] * 4
    assert [float(image.mean()) for image in images] == pytest.approx([20, 50, 80, 110], abs=2)


# -- upload file names ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("raw", "name"),
    [
        # an escape sequence that would colour a terminal, a bell, a tab
        (b"cam\x1b[31m1\x07\t.avi", "cam[31m1.avi"),
        # a newline sent raw or as the form's %0A: a forged log line
        (b"gate\n2026-01-01 ERROR x.avi", "gate2026-01-01 ERROR x.avi"),
        (b"gate%0D%0Ax.avi", "gatex.avi"),
        # C1 controls (UTF-8 encoded) and DEL
        ("a\u0085b\u009bc\x7f.avi".encode(), "abc.avi"),
        # the form's %22 is a quote, and letters of any script stay
        (b"cam%22\xc3\xa9ra\xe2\x80\x8c.avi", 'cam"\u00e9ra\u200c.avi'),
        # nothing left: no name
        (b"\x01\x02", None),
    ],
)
def test_control_characters_leave_upload_file_names(raw, name):
    assert _client_filename(raw) == name


# -- a real service: stalled headers and bodies, oversized frames, names -------------------------


def _request(port: int, data: bytes) -> socket.socket:
    connection = socket.create_connection(("127.0.0.1", port), timeout=30)
    connection.sendall(data)
    return connection


def _answer(connection: socket.socket) -> tuple[int, dict[str, str], bytes] | None:
    """The HTTP answer read from ``connection`` (status, headers, body), or None when the
    server closed it without one."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = connection.recv(65536)
        if not chunk:
            return None if not data else _parse(data)
        data += chunk
    return _parse(data, connection)


def _parse(data: bytes, connection: socket.socket | None = None):
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    headers = {
        k.strip().lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])
    }
    length = int(headers.get("content-length", 0))
    while connection is not None and len(body) < length:
        chunk = connection.recv(65536)
        if not chunk:
            break
        body += chunk
    return int(lines[0].split()[1]), headers, body


def _multipart(filename: bytes, video: bytes, options: dict) -> tuple[bytes, bytes]:
    """A job's upload body with a raw ``filename`` (bytes as a client may send them), and its
    boundary."""
    boundary = b"vtrack-limits"
    body = (
        b"--"
        + boundary
        + b'\r\nContent-Disposition: form-data; name="options"\r\n\r\n'
        + json.dumps(options).encode()
        + b"\r\n--"
        + boundary
        + b'\r\nContent-Disposition: form-data; name="video"; filename="'
        + filename
        + b'"\r\n'
        + b"Content-Type: video/x-msvideo\r\n\r\n"
        + video
        + b"\r\n--"
        + boundary
        + b"--\r\n"
    )
    return body, boundary


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    server = Server(
        tmp_path_factory.mktemp("limits-server") / "data",
        workers=1,
        header_seconds=1,
        body_idle_seconds=1,
        upload_idle_seconds=1,
        max_upload_bytes=5_000_000,
    ).start()
    yield server
    server.stop()


def _timed_answer(server: Server, data: bytes):
    started = time.monotonic()
    with _request(server.port, data) as connection:
        answer = _answer(connection)
        return answer, time.monotonic() - started


def test_a_stalled_request_line_gets_408_and_a_silent_connection_is_closed(server):
    # before: held for ever, and with no limit on their number
    answer, seconds = _timed_answer(server, b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n")
    assert answer is not None and answer[0] == 408, answer
    # the family's whole sentence, once
    assert json.loads(answer[2]) == {
        "type": "timeout",
        "detail": "the request's headers did not arrive within 1 s (VTRACK_HEADER_SECONDS)",
    }
    assert answer[1]["connection"] == "close"
    assert 0.8 < seconds < 10
    answer, seconds = _timed_answer(server, b"")
    assert answer is None and 0.8 < seconds < 10
    assert "closed (408): the request's headers did not arrive within 1 s" in server.log()


def test_headers_that_never_end_get_431(server):
    endless = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n" + b"X-Filler: 0123456789\r\n" * 4000
    answer, seconds = _timed_answer(server, endless)
    assert answer is not None and answer[0] == 431, answer
    # the family's whole sentence
    assert json.loads(answer[2]) == {
        "type": "headers_too_large",
        "detail": "the request's line and headers are over 64 KiB",
    }
    assert seconds < 5  # at once, not at the deadline


def test_a_stalled_oversized_upload_gets_its_413_within_the_idle_time(server):
    # before: the 413 waited for 64 MiB to drain that never came
    head = (
        b"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 10000000000\r\n"
        b"Content-Type: multipart/form-data; boundary=x\r\n\r\n"
    )
    answer, seconds = _timed_answer(server, head)
    assert answer is not None and answer[0] == 413, answer
    assert json.loads(answer[2])["type"] == "payload_too_large"
    assert seconds < 10


def test_a_stalled_request_body_gets_408(server):
    # a stream's settings announced and never sent: before, the connection was held for ever
    head = (
        b"POST /v1/streams HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        b"Content-Length: 100\r\n\r\n{"
    )
    answer, seconds = _timed_answer(server, head)
    assert answer is not None and answer[0] == 408, answer
    refusal = json.loads(answer[2])
    assert refusal["type"] == "timeout" and "after 1 bytes" in refusal["detail"]
    assert 0.8 < seconds < 10


def test_a_job_with_an_oversized_frame_fails_naming_it_and_the_service_goes_on(server, videos):
    with server.client() as client:
        files = {"video": ("camera 7.avi", videos["avi"].read_bytes(), "video/x-msvideo")}
        created = client.post("/v1/jobs", files=files, data={"options": json.dumps(SINGLE)})
        assert created.status_code == 202, created.text  # its headers and first frame are fine
        failed = wait_for_state(client, created.json()["id"], ("succeeded", "failed"), 60)
        assert failed["state"] == "failed"
        assert failed["error"] == (
            "the job could not run: frame 3 of 'camera 7.avi' (counting from 0) is 8208x8192 "
            "pixels, more than this service takes (67 megapixels, 8192x8192): the video changes "
            "its frame size after its start (64x48); send a video whose frames all keep that size"
        )
        assert not (server.data_dir / "results" / failed["id"]).exists()  # no partial results
        # the same worker takes the next job
        files = {"video": ("plain.avi", videos["plain"].read_bytes(), "video/x-msvideo")}
        created = client.post("/v1/jobs", files=files, data={"options": json.dumps(SINGLE)})
        done = wait_for_state(client, created.json()["id"], ("succeeded", "failed"), 60)
        assert done["state"] == "succeeded", done


def test_an_uploads_file_name_is_kept_without_its_control_characters(server, videos):
    body, boundary = _multipart(
        b"gate\x1b[2J%0D%0A7\x07\t\x7f.avi", videos["plain"].read_bytes(), SINGLE
    )
    with server.client() as client:
        created = client.post(
            "/v1/jobs",
            content=body,
            headers={"Content-Type": f"multipart/form-data; boundary={boundary.decode()}"},
        )
        assert created.status_code == 202, created.text
        done = wait_for_state(client, created.json()["id"], ("succeeded", "failed"), 60)
        assert done["state"] == "succeeded", done
        assert done["video_filename"] == "gate[2J7.avi"
        result = client.get(f"/v1/jobs/{done['id']}/result?format=json").json()
    assert result["video"]["filename"] == "gate[2J7.avi"


# -- the connection cap -----------------------------------------------------------------------


def test_connections_over_the_cap_get_503_and_the_service_answers_after(tmp_path):
    server = Server(tmp_path / "data", workers=1, max_connections=2).start()
    try:
        holders = []
        for _ in range(2):  # two requests whose bodies the service waits for
            holder = _request(
                server.port,
                b"POST /v1/streams HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json"
                b"\r\nContent-Length: 100\r\nExpect: 100-continue\r\n\r\n",
            )
            assert holder.recv(100).startswith(b"HTTP/1.1 100 "), "the request is being read"
            holders.append(holder)
        answer, _ = _timed_answer(server, b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert answer is not None and answer[0] == 503, answer
        # the family's whole sentence, once
        assert json.loads(answer[2]) == {
            "type": "busy",
            "detail": "the service has as many connections open as it serves at once "
            "(VTRACK_MAX_CONNECTIONS): try again in a moment",
        }
        assert answer[1]["retry-after"] == "1" and answer[1]["connection"] == "close"
        for holder in holders:
            holder.close()

        def answers() -> bool:
            answer, _ = _timed_answer(server, b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            return answer is not None and answer[0] == 200

        wait_for(answers, 10, "the service to answer again")
        assert "Traceback" not in server.log()  # the held requests' clients went away
    finally:
        server.stop()


# -- the temporary folder ------------------------------------------------------------------------


def test_a_start_and_stop_leave_no_folder_in_the_systems_temporary_folder(tmp_path, monkeypatch):
    # before: a pymp-* folder (multiprocessing's, with the fork server's socket) at every start
    # and stop by SIGTERM, as service managers stop it
    system_temp = tmp_path / "t"  # a short path: the fork server's socket goes in it
    system_temp.mkdir()
    monkeypatch.setenv("TMPDIR", str(system_temp))
    server = Server(tmp_path / "data", workers=1).start()
    assert [path.name[:5] for path in system_temp.iterdir()] == ["pymp-"]
    server.stop()
    assert server.process is not None and server.process.returncode == -signal.SIGTERM
    assert list(system_temp.iterdir()) == []
