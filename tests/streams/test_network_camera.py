"""Network cameras as the source of ``vtrack publish``: real TCP and HTTP servers on loopback,
read by FFmpeg as a camera's RTSP or MPEG-TS stream is read."""

from __future__ import annotations

import io
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
from fractions import Fraction
from itertools import islice
from pathlib import Path

import av
import numpy as np
import pytest

from devtools.simulated_cameras import (
    FileServer,
    RtspCamera,
    TcpCamera,
    access_units,
    h264_video,
)
from devtools.testing import free_port, wait_for
from service.outputs.h264 import (
    IDR,
    PPS,
    SPS,
    nal_unit_types,
    nal_units,
    picture_count,
)
from service.streams.capture_clock import SLEW
from service.streams.network_camera import (
    SEVERAL_FRAMES,
    STREAM_SCHEMES,
    UNTIMED,
    CameraConnection,
    CameraSettings,
    CameraUnavailable,
    NetworkCamera,
    is_stream_url,
    redacted,
)
from service.streams.payloads import H264Frames
from service.streams.tools import video_frames
from tests.conftest import REPO_ROOT
from tests.service.conftest import PETS_VIDEO
from tests.service.test_limits import OVER, write_mjpeg

pytestmark = pytest.mark.realtime  # cameras send at their frame rate; delays are measured

FRAMES = 40


@pytest.fixture(scope="module")
def pets(shared_data) -> list[np.ndarray]:
    frames, _ = video_frames(str(shared_data / PETS_VIDEO))
    return list(islice(frames, FRAMES))


@pytest.fixture(scope="module")
def transport_stream(pets) -> bytes:
    """40 PETS frames as a camera's MPEG-TS: H.264 without B-frames, a key frame a second."""
    return h264_video(pets, "mpegts")


@pytest.fixture(scope="module")
def files(tmp_path_factory, pets, shared_data) -> FileServer:
    """An HTTP server with an MP4 from a camera (H.264 in avcC form), the PETS AVI (H.264 with
    B-frames), a login page and a text file."""
    folder = tmp_path_factory.mktemp("http")
    h264_video(pets[:30], "mp4", folder / "camera.mp4")
    shutil.copy(shared_data / PETS_VIDEO, folder / "b_frames.avi")
    (folder / "login.html").write_text("<html><body>Please log in</body></html>")
    (folder / "readme.txt").write_text("not a video\n" * 100)
    server = FileServer(folder)
    yield server
    server.close()


@pytest.fixture
def camera(transport_stream, request) -> TcpCamera:
    plan = getattr(request, "param", ("whole",))
    camera = TcpCamera(transport_stream, plan)
    yield camera
    camera.close()


def decoded(stream: bytes) -> list[np.ndarray]:
    """Every frame of a video held in memory, as FFmpeg decodes it from a file."""
    with av.open(io.BytesIO(stream)) as container:
        return [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]


def test_a_camera_frame_over_the_size_limit_is_refused_before_it_is_converted(tmp_path):
    # before: `vtrack publish` converted whatever size a camera stated (8208x8192 here; a few
    # bytes of H.264 can state 16000x16000, 0.8 GB once converted)
    write_mjpeg(tmp_path / "huge.avi", [(64, 48), (64, 48), OVER, (64, 48)])
    server = FileServer(tmp_path)
    try:
        connection = CameraConnection(server.url("huge.avi"), CameraSettings(), False)
        items = connection.items()
        assert [next(items)[0].shape for _ in range(2)] == [(48, 64, 3)] * 2
        with pytest.raises(CameraUnavailable) as refused:
            next(items)
    finally:
        server.close()
    assert refused.value.reason.startswith("a frame of 8208x8192 pixels, more than this service")


def test_stream_urls_are_told_from_paths_and_passwords_are_hidden():
    assert is_stream_url("rtsp://10.0.0.7:554/stream1")
    assert is_stream_url("HTTPS://cam.example/video.mjpg")
    assert not is_stream_url("videos/gate.mp4")
    assert not is_stream_url("webcam:0")
    assert not is_stream_url("file:///videos/gate.mp4")  # a file: paced at its frame rate
    assert redacted("rtsp://admin:s3cret@10.0.0.7:554/h264") == "rtsp://admin:***@10.0.0.7:554/h264"
    assert redacted("rtsp://10.0.0.7/h264") == "rtsp://10.0.0.7/h264"


def test_a_tcp_camera_gives_the_frames_it_sends(camera, transport_stream):
    connection = CameraConnection(camera.url, CameraSettings(), forward_h264=False)
    assert not connection.forwarding and connection.whole_frames
    assert connection.description == "h264 480x360"
    frames, positions = zip(*connection.items(), strict=True)
    expected = decoded(transport_stream)
    assert len(frames) == len(expected) == FRAMES
    assert all(np.array_equal(f, e) for f, e in zip(frames, expected, strict=True))
    # with their presentation times: the camera's 10 frames a second
    np.testing.assert_allclose(np.diff(positions), 0.1, atol=1e-6)


def _listening_udp(port: int) -> bool:
    """Whether a UDP socket of this machine is bound to ``port`` (Linux's table of them)."""
    tables = (Path("/proc/net/udp"), Path("/proc/net/udp6"))
    return any(f":{port:04X} " in t.read_text() for t in tables if t.exists())


def test_an_mpegts_camera_over_udp_gives_the_frames_it_sends(transport_stream):
    # As an encoder sends MPEG-TS to udp://host:port: seven TS packets per datagram, 10 fps.
    port = free_port()
    frames = TcpCamera.split(transport_stream)

    def send() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            wait_for(lambda: _listening_udp(port), 10, "the gateway to listen")
            for frame in frames:
                for at in range(0, len(frame), 7 * 188):
                    sender.sendto(frame[at : at + 7 * 188], ("127.0.0.1", port))
                time.sleep(0.1)  # the camera's 10 fps: the presentation times are tested

    threading.Thread(target=send, daemon=True).start()
    connection = CameraConnection(f"udp://127.0.0.1:{port}", CameraSettings(5.0, 1.0), False)
    assert connection.whole_frames and connection.description == "h264 480x360"
    received = []
    with pytest.raises(CameraUnavailable, match="no data for 1 s"):  # the encoder stopped
        for frame, position in connection.items():
            received.append((frame, position))
    assert len(received) == FRAMES
    expected = decoded(transport_stream)
    assert all(np.array_equal(f, e) for (f, _), e in zip(received, expected, strict=True))
    np.testing.assert_allclose(np.diff([p for _, p in received]), 0.1, atol=1e-6)


def test_h264_without_b_frames_is_forwarded_as_the_camera_encoded_it(camera, transport_stream):
    connection = CameraConnection(camera.url, CameraSettings(), forward_h264=True)
    assert connection.forwarding
    assert connection.description.endswith("forwarded as the camera encoded it")
    units, positions = map(list, zip(*connection.items(), strict=True))
    with av.open(io.BytesIO(transport_stream)) as container:
        packets = [p for p in container.demux(video=0) if p.size]
    assert units == [bytes(p) for p in packets]  # byte for byte: nothing decoded or encoded
    assert positions == [float(p.pts * p.time_base) for p in packets]
    # The service's live decoder turns each unit into its frame, as a file decoder does.
    service = H264Frames()
    expected = decoded(transport_stream)
    assert all(np.array_equal(service.decode(u), e) for u, e in zip(units, expected, strict=True))


@pytest.fixture(scope="module")
def camera_units(pets) -> list[bytes]:
    """The PETS frames as a camera's H.264 access units (Annex B), 10 frames a second."""
    return access_units(pets)


def transport_stream_of(packets: list[tuple[bytes, int]]) -> bytes:
    """MPEG-TS with one PES packet per ``(payload, time in 1/90000 s)``, as given: a muxer
    that packs frames as it likes."""
    buffer = io.BytesIO()
    with av.open(buffer, "w", format="mpegts") as output:
        stream = output.add_stream("libx264", rate=10)
        stream.width, stream.height = 480, 360
        for payload, pts in packets:
            packet = av.Packet(payload)
            packet.pts = packet.dts = pts
            packet.time_base, packet.stream = Fraction(1, 90000), stream
            output.mux(packet)
    return buffer.getvalue()


@pytest.mark.parametrize("forward", [False, True])
def test_an_mpegts_frame_comes_out_once_the_next_one_starts(pets, forward):
    # FFmpeg's parser would hold a frame until the frame after it starts: a frame later.
    camera = TcpCamera(h264_video(pets[:30], "mpegts"), fps=20)
    try:
        connection = CameraConnection(camera.url, CameraSettings(), forward_h264=forward)
        assert connection.whole_frames and connection.forwarding == forward
        sent = [len(camera.taken) - index for index, _ in enumerate(connection.items())]
    finally:
        camera.close()
    assert len(sent) == 30
    # Frame k (from 0) is out once frame k + 1 has been sent, as the demuxer sees where a
    # frame's packet ends when the next one begins: the camera has then taken k + 3 frames
    # (frame k + 2 waits for its time), and k + 4 with the parser. The first frames come out
    # after the stream study, the last when the stream ends.
    assert np.median(sent[5:-3]) == 3


def test_a_stream_with_several_frames_in_a_packet_is_read_with_the_parser(camera_units, pets):
    # Read packet by packet, the decoder would give only a packet's first frame.
    pairs = [(b"".join(camera_units[i : i + 2]), i * 9000) for i in range(0, FRAMES, 2)]
    camera = TcpCamera(transport_stream_of(pairs))
    news: list[str] = []
    try:
        source = NetworkCamera(camera.url, tell=news.append)
        frames = [item.data for item in islice(source, FRAMES)]
    finally:
        camera.close()
    assert news[0] == (
        f"{camera.url}: {SEVERAL_FRAMES}: reading it with FFmpeg's parser (a frame later); "
        "connecting again in 1 s"
    )
    assert source.connections == 2 and not source.connection.whole_frames
    assert all(np.abs(f.astype(np.int16) - p).mean() < 6 for f, p in zip(frames, pets, strict=True))


def test_parameter_sets_in_a_packet_of_their_own_are_forwarded_with_their_frame(camera_units):
    def pieces(unit: bytes) -> list[bytes]:  # the NAL units before the first slice, the rest
        nals = nal_units(unit)
        first = next(i for i, nal in enumerate(nals) if picture_count(b"\0\0\1" + nal))
        pieces = [nals[:first], nals[first:]]
        return [b"".join(b"\0\0\0\1" + nal for nal in piece) for piece in pieces if piece]

    packets = []
    for i, unit in enumerate(camera_units):
        split = pieces(unit)
        packets += [(piece, i * 9000 - len(split) + 1 + j) for j, piece in enumerate(split)]
    assert len(packets) == FRAMES + 4  # four key frames
    camera = TcpCamera(transport_stream_of(packets))
    try:
        connection = CameraConnection(camera.url, CameraSettings(), forward_h264=True)
        assert connection.whole_frames
        units = [unit for unit, _ in connection.items()]
    finally:
        camera.close()
    assert len(units) == FRAMES and all(picture_count(u) == 1 for u in units)
    keys = [types for u in units if IDR in (types := nal_unit_types(u))]
    assert len(keys) == 4 and all(SPS in types and PPS in types for types in keys)
    service = H264Frames()
    reference = H264Frames()
    for unit, original in zip(units, camera_units, strict=True):
        assert np.array_equal(service.decode(unit), reference.decode(original))


def test_an_rtsp_camera_is_forwarded_with_the_parameter_sets_of_its_description(camera_units, pets):
    # The camera states SPS and PPS in its session description only; the service's decoder
    # needs them in the stream, before the first key frame.
    camera = RtspCamera(camera_units, fps=20)
    try:
        connection = CameraConnection(camera.url, CameraSettings(), forward_h264=True)
        assert connection.description == "h264 480x360, forwarded as the camera encoded it"
        forwarded = [unit for unit, _ in connection.items()]
        decoding = CameraConnection(camera.url, CameraSettings(), forward_h264=False)
        frames = [frame for frame, _ in decoding.items()]
    finally:
        camera.close()
    assert len(forwarded) == len(frames) == FRAMES
    # Every key frame (one a second) carries them, so a tracker can join at any of them.
    keys = [types for u in forwarded if IDR in (types := nal_unit_types(u))]
    assert len(keys) == 4 and all(types[:2] == [SPS, PPS] for types in keys)
    service = H264Frames()
    for unit, frame, sent in zip(forwarded, frames, pets, strict=True):
        picture = service.decode(unit)
        assert np.array_equal(picture, frame)  # forwarded or decoded: the same pictures
        assert np.abs(picture.astype(np.int16) - sent.astype(np.int16)).mean() < 6


def test_frames_are_stamped_with_the_time_the_camera_took_them(pets):
    # FFmpeg studies an RTSP stream for up to a second before the first frame, then hands over
    # what came meanwhile at once: stamped on arrival, those frames would be one instant.
    camera = RtspCamera(access_units(pets, fps=20), fps=20)
    try:
        source = NetworkCamera(camera.url)
        received = np.array([(item.time, time.time()) for item in islice(source, FRAMES)])
    finally:
        camera.close()
    stamps, arrivals = received.T
    assert np.diff(arrivals).min() < 0.005  # the burst
    # FFmpeg gives the first RTP packet no time (a frame without one is stamped on arrival);
    # from the second on, the camera's 20 frames a second
    spacing = np.diff(stamps[1:])
    assert spacing.min() > 0.05 * (1 - SLEW) - 1e-6 and spacing.max() < 0.05 * (1 + SLEW) + 1e-6
    assert abs(stamps[-1] - arrivals[-1]) < 1.0


def test_a_stream_whose_times_do_not_keep_pace_is_stamped_on_arrival():
    # The stream says 25 frames a second; the camera sends 250.
    frames = [np.full((48, 64, 3), i % 256, np.uint8) for i in range(700)]
    camera = TcpCamera(h264_video(frames, "mpegts", fps=25), fps=250)
    news: list[str] = []
    try:
        source = NetworkCamera(camera.url, tell=news.append)
        received = np.array([(item.time, time.time()) for item in islice(source, 650)])
    finally:
        camera.close()
    assert news == [f"{camera.url}: {UNTIMED}"]
    stamps, arrivals = received.T
    # spaced as they arrived (within the clock's slew back to arrival times), neither 40 ms
    # apart nor standing still: the last 100 span about 0.4 s, not 4 or 0. Compared over the
    # span, not frame by frame, since this loop reads the clock a scheduling delay after the
    # stamp (milliseconds under load).
    assert np.all(np.diff(stamps) >= 0)
    span, arrived = stamps[-1] - stamps[-100], arrivals[-1] - arrivals[-100]
    assert abs(span - arrived) <= SLEW * arrived + 0.05


def test_an_mp4_over_http_is_forwarded_in_annex_b_form(files, pets):
    connection = CameraConnection(files.url("camera.mp4"), CameraSettings(), forward_h264=True)
    assert connection.forwarding
    assert not connection.whole_frames  # opened again with the parser: not MPEG-TS
    units = [unit for unit, _ in connection.items()]
    assert len(units) == 30
    assert all(u.startswith((b"\x00\x00\x00\x01", b"\x00\x00\x01")) for u in units)
    first = nal_unit_types(units[0])
    assert SPS in first and IDR in first  # parameter sets ride with the key frame
    service = H264Frames()
    for unit, frame in zip(units, pets, strict=False):
        error = np.abs(service.decode(unit).astype(np.int16) - frame.astype(np.int16)).mean()
        assert error < 6


def test_h264_with_b_frames_is_decoded_into_frames_instead(files, pets):
    connection = CameraConnection(files.url("b_frames.avi"), CameraSettings(), forward_h264=True)
    assert not connection.forwarding
    assert "B-frames" in connection.description
    items = connection.items()
    frames = [frame for frame, _ in islice(items, 5)]
    items.close()
    assert all(np.array_equal(f, p) for f, p in zip(frames, pets, strict=False))


def test_b_frames_found_while_forwarding_are_decoded_from_the_next_connection(pets):
    # A camera joined between key frames, opened without study (the user's FFmpeg options):
    # nothing tells of B-frames until the frames come out of order.
    stream = h264_video(pets, "mpegts", b_frames=2)
    camera = TcpCamera(stream[len(stream) // 8 // 188 * 188 :])
    news: list[str] = []
    settings = CameraSettings(options={"analyzeduration": "0", "probesize": "32"})
    try:
        source = NetworkCamera(camera.url, settings, forward_h264=True, tell=news.append)
        assert source.connection.forwarding
        items = [item.data for item in islice(source, 10)]
    finally:
        camera.close()
    assert news[0] == (
        f"{camera.url}: the camera's H.264 has B-frames, which a live decoder cannot take unit "
        "by unit: decoding it instead; connecting again in 1 s"
    )
    assert not source.connection.forwarding
    frames = [item for item in items if isinstance(item, np.ndarray)]
    assert frames and all(f.shape == (360, 480, 3) for f in frames)
    # Units forwarded before the order gave the B-frames away (none when it shows before the
    # first key frame) start at a key frame.
    units = items[: len(items) - len(frames)]
    assert all(isinstance(u, bytes) for u in units)
    assert not units or IDR in nal_unit_types(units[0])


@pytest.mark.parametrize("camera", [("drop", "whole")], indirect=True)
def test_a_camera_that_drops_is_connected_to_again(camera):
    news: list[str] = []
    source = NetworkCamera(camera.url, forward_h264=True, tell=news.append)
    units = [item.data for item in islice(source, FRAMES + 5)]  # half a stream, then all
    assert source.connections == 2 and camera.connections == 2
    assert news[0] == f"{camera.url}: the stream ended; connecting again in 1 s"
    assert news[1].startswith(f"{camera.url}: connected again (h264 480x360")
    # Each connection starts at a key frame, so the service can decode across the drop.
    service = H264Frames()
    assert all(service.decode(u).shape == (360, 480, 3) for u in units)


@pytest.mark.parametrize("camera", [("stall", "whole")], indirect=True)
def test_a_camera_that_stalls_is_lost_after_the_timeout_and_connected_to_again(camera):
    news: list[str] = []
    settings = CameraSettings(read_timeout=1.0)
    source = NetworkCamera(camera.url, settings, tell=news.append)
    frames = list(islice(source, FRAMES + 5))
    assert len(frames) == FRAMES + 5 and source.connections == 2
    assert news[0] == (
        f"{camera.url}: the stream broke off (no data for 1 s); connecting again in 1 s"
    )


def test_a_camera_that_stays_away_is_tried_again_less_and_less_often(transport_stream):
    camera = TcpCamera(transport_stream, ("drop",))
    news: list[str] = []
    stop = threading.Event()

    def tell(line: str) -> None:
        news.append(line)
        if "trying again in 4 s" in line:
            stop.set()  # seen the waits double: stop instead of waiting 4 s

    source = NetworkCamera(camera.url, forward_h264=True, tell=tell, stop=stop)
    camera.close()  # the camera goes away after its first half stream
    units = [item.data for item in source]  # ends when stopped
    assert units and IDR in nal_unit_types(units[0])
    assert news[0].endswith("the stream ended; connecting again in 1 s")
    assert news[1] == f"cannot open {camera.url}: Connection refused; trying again in 2 s"
    assert news[2] == f"cannot open {camera.url}: Connection refused; trying again in 4 s"


@pytest.mark.parametrize("scheme", sorted(STREAM_SCHEMES))
def test_every_scheme_taken_for_a_camera_is_one_ffmpeg_reads(scheme):
    port = free_port()
    with pytest.raises(CameraUnavailable) as raised:  # nothing answers there
        CameraConnection(f"{scheme}://127.0.0.1:{port}/x", CameraSettings(1.0, 1.0), False)
    assert "Protocol not found" not in str(raised.value)


def test_what_is_not_a_camera_is_a_clear_error(files):
    url = unused_url()
    login, readme = files.url("login.html"), files.url("readme.txt")
    for source, message in [
        (url, f"cannot open {url}: Connection refused"),
        (files.url("missing.mp4"), "Server returned 404 Not Found"),
        (login, f"cannot open {login}: Invalid data found when processing input"),
        (readme, f"{readme} sends no video"),
    ]:
        with pytest.raises(CameraUnavailable, match=re.escape(message)):
            CameraConnection(source, CameraSettings(), forward_h264=False)
    with pytest.raises(CameraUnavailable) as raised:
        CameraConnection("rtsp://admin:s3cret@127.0.0.1:9/h264", CameraSettings(), False)
    assert "s3cret" not in str(raised.value) and "admin:***@" in str(raised.value)


def unused_url() -> str:
    """A loopback TCP URL where nothing listens (a port just freed)."""
    return f"tcp://127.0.0.1:{free_port()}"


def publish(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "service.cli", "publish", *args],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_publish_refuses_an_unreachable_camera_and_file_options_for_a_camera():
    url = unused_url()
    # Refused before any Zenoh session is opened: nothing listens on port 9 either.
    result = publish(url, "--camera", "gate", "--connect", "tcp/127.0.0.1:9")
    assert result.returncode == 2
    assert f"vtrack publish: cannot open {url}: Connection refused" in result.stderr
    for option in (["--fps", "5"], ["--loop"]):
        result = publish("rtsp://10.0.0.7/h264", "--camera", "gate", *option)
        assert result.returncode == 2
        assert "--fps and --loop are for files: a network camera sends at its own rate" in (
            result.stderr
        )
    result = publish("rtsp://10.0.0.7/h264", "--camera", "gate", "--input-option", "udp")
    assert result.returncode == 2 and "expected KEY=VALUE, got 'udp'" in result.stderr
