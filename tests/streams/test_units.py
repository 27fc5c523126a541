"""Unit tests of the live-stream building blocks: payloads, the worker's slots, keys, Zenoh
configuration, the stream schemas, and one real Zenoh round trip through the publish tool."""

from __future__ import annotations

import dataclasses
import json
import socket
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import zenoh
from pydantic import ValidationError

from api_schemas.streams import (
    FrameAttachment,
    PixelFormat,
    StreamSpec,
    StreamTracksMessage,
    UpstreamDetection,
    UpstreamDetections,
)
from api_schemas.tracks import FrameTracksMessage
from service.streams import tools
from service.streams.capture_clock import Captured
from service.streams.keys import StreamKeys
from service.streams.payloads import (
    JPEG,
    RAW,
    H264Frames,
    PayloadError,
    check_frame_size,
    decode_frame,
    encode_jpeg,
    frame_attachment,
    parse_attachment,
    parse_detections,
    to_detections,
)
from service.streams.security import AccessRules, TlsFiles, ZenohSecurity
from service.streams.session import (
    ZenohOptions,
    ZenohUnavailable,
    open_session,
    wait_for_neighbour,
)
from service.streams.simulated_cameras import access_units
from service.streams.store import StreamStore
from service.streams.worker import Incoming, LatestFrame, UpstreamBuffer
from service.testing import free_port, wait_for
from tracking.detection.base import Detections
from tracking.detection.external import detections_from_arrays

VIDEO = Path("video") / "pets09_s2l1_480x360.avi"


@pytest.fixture(scope="module")
def first_frame(shared_data: Path) -> np.ndarray:
    """The first frame of the PETS09-S2L1 video, RGB."""
    capture = cv2.VideoCapture(str(shared_data / VIDEO))
    try:
        ok, bgr = capture.read()
    finally:
        capture.release()
    assert ok, f"cannot read {shared_data / VIDEO}"
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def raw_attachment(width: int, height: int, fmt: str, sequence: int = 0) -> FrameAttachment:
    data = frame_attachment(sequence, 1.5, width=width, height=height, format=fmt)
    return parse_attachment(data)


# -- payloads: attachments ---------------------------------------------------------------------


@pytest.mark.parametrize("attachment", [None, b""])
def test_parse_attachment_missing(attachment):
    with pytest.raises(PayloadError, match="attachment"):
        parse_attachment(attachment)


def test_parse_attachment_and_detections_have_size_limits():
    # before: any size was parsed (a 30 MB attachment with every frame, in JSON)
    padded = b'{"sequence": 1, "timestamp": 1.0, "note": "' + b"x" * 5000 + b'"}'
    with pytest.raises(PayloadError, match="frame attachment of 5045 bytes is over the limit"):
        parse_attachment(padded)
    many = b'{"sequence": 1, "detections": [' + b'{"x":1,"y":1,"w":2,"h":2,"score":1},' * 40000
    with pytest.raises(PayloadError, match=r"detections message of \d+ bytes is over the limit"):
        parse_detections(many + b"{}]}")


def test_parse_attachment_invalid_json():
    with pytest.raises(PayloadError, match="bad frame attachment"):
        parse_attachment(b"{not json")


def test_parse_attachment_missing_timestamp():
    with pytest.raises(PayloadError, match="timestamp"):
        parse_attachment(b'{"sequence": 3}')


def test_parse_attachment_negative_sequence():
    with pytest.raises(PayloadError, match="sequence"):
        parse_attachment(b'{"sequence": -1, "timestamp": 1.0}')


def test_parse_attachment_valid():
    got = parse_attachment(b'{"sequence": 7, "timestamp": 12.25, "extra": "ignored"}')
    assert got == FrameAttachment(sequence=7, timestamp=12.25)
    assert got.width is None and got.height is None and got.format is None


def test_frame_attachment_round_trip():
    data = frame_attachment(42, 1700000000.125, width=4, height=2, format="bgr8")
    assert isinstance(data, bytes)
    got = parse_attachment(data)
    assert (got.sequence, got.timestamp) == (42, 1700000000.125)
    assert (got.width, got.height, got.format) == (4, 2, PixelFormat.bgr8)
    assert parse_attachment(frame_attachment(0, 0.0)) == FrameAttachment(sequence=0, timestamp=0)


# -- payloads: frames --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def h264_units(shared_data: Path) -> tuple[list[np.ndarray], list[bytes]]:
    """30 PETS frames (RGB) and their H.264 units, 0.1 s apart: key frames at 0, 1 and 2 s."""
    capture = cv2.VideoCapture(str(shared_data / VIDEO))
    frames = [cv2.cvtColor(capture.read()[1], cv2.COLOR_BGR2RGB) for _ in range(30)]
    capture.release()
    return frames, access_units(frames)


def test_h264_units_decode_to_their_frames(h264_units):
    frames, units = h264_units
    stream = H264Frames()
    for frame, unit in zip(frames, units, strict=True):
        decoded = stream.decode(unit)
        assert decoded.shape == (360, 480, 3) and decoded.dtype == np.uint8
        assert np.abs(decoded.astype(np.int16) - frame.astype(np.int16)).mean() < 6


def test_an_h264_stream_joined_late_waits_for_a_key_frame(h264_units):
    frames, units = h264_units
    stream = H264Frames()
    for unit in units[3:10]:  # the camera's stream from its 4th frame: no key frame yet
        with pytest.raises(PayloadError, match="before the first key frame"):
            stream.decode(unit)
    for frame, unit in zip(frames[10:], units[10:], strict=True):  # key frame at 1.0 s
        assert np.abs(stream.decode(unit).astype(np.int16) - frame.astype(np.int16)).mean() < 6


def test_bad_h264_units_are_refused_and_the_stream_goes_on(h264_units):
    frames, units = h264_units
    stream = H264Frames()
    stream.decode(units[0])
    with pytest.raises(PayloadError, match="video/h264 unit of 13 bytes does not decode"):
        stream.decode(b"not h264 data")
    with pytest.raises(PayloadError, match="empty video/h264 unit"):
        stream.decode(b"")
    for frame, unit in zip(frames[10:13], units[10:13], strict=True):  # from the next key frame
        assert np.abs(stream.decode(unit).astype(np.int16) - frame.astype(np.int16)).mean() < 6


def test_an_h264_frame_over_the_pixel_limit_is_refused(h264_units, monkeypatch):
    from service.streams import payloads

    monkeypatch.setattr(payloads, "MAX_PIXELS", 480 * 360 - 1)  # as an 8K+ frame would be
    with pytest.raises(PayloadError, match="frame of 480x360 is larger than this service takes"):
        H264Frames().decode(h264_units[1][0])


@pytest.mark.parametrize("encoding", [".jpg", ".png"])
def test_an_image_stating_more_pixels_than_the_limit_is_refused_before_decoding(
    first_frame, encoding
):
    # before: a 6 MB JPEG of 20000x20000 was decoded, its worker grew by 1.2 GB per frame
    ok, data = cv2.imencode(encoding, first_frame)
    assert ok
    header = bytearray(data.tobytes())
    big = (20000).to_bytes(2, "big")
    if encoding == ".png":  # IHDR: width and height, 4 bytes each
        header[16:24] = (20000).to_bytes(4, "big") * 2
    else:  # the start-of-frame segment: height, then width
        sof = next(i for i in range(2, len(header)) if header[i : i + 2] == b"\xff\xc0")
        header[sof + 5 : sof + 9] = big + big
    with pytest.raises(PayloadError, match="frame of 20000x20000 is larger than this service"):
        decode_frame(bytes(header), "image/x", parse_attachment(frame_attachment(0, 0.0)))
    # the real one still decodes
    decoded = decode_frame(data.tobytes(), "image/x", parse_attachment(frame_attachment(0, 0.0)))
    assert decoded.shape == (360, 480, 3)


def test_decode_jpeg_of_a_real_frame(first_frame):
    payload = encode_jpeg(first_frame)
    assert payload[:2] == b"\xff\xd8"  # JPEG SOI marker
    decoded = decode_frame(payload, JPEG, parse_attachment(frame_attachment(0, 0.0)))
    assert decoded.shape == first_frame.shape == (360, 480, 3)
    assert decoded.dtype == np.uint8
    diff = np.abs(decoded.astype(np.int16) - first_frame.astype(np.int16))
    assert diff.mean() < 3.0
    # Channel order survives: swapping R and B would be far off on a real scene.
    swapped = np.abs(decoded[..., ::-1].astype(np.int16) - first_frame.astype(np.int16))
    assert swapped.mean() > diff.mean() + 1.0


def test_decode_raw_rgb8():
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    decoded = decode_frame(rgb.tobytes(), RAW, raw_attachment(3, 2, "rgb8"))
    np.testing.assert_array_equal(decoded, rgb)
    assert decoded.flags.writeable


def test_decode_raw_bgr8_swaps_channels():
    bgr = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3) * 7
    decoded = decode_frame(bgr.tobytes(), RAW, raw_attachment(3, 2, "bgr8"))
    np.testing.assert_array_equal(decoded, bgr[..., ::-1])


def test_decode_raw_mono8_replicates():
    mono = np.array([[0, 10, 20], [30, 40, 255]], dtype=np.uint8)
    decoded = decode_frame(mono.tobytes(), RAW, raw_attachment(3, 2, "mono8"))
    assert decoded.shape == (2, 3, 3)
    for channel in range(3):
        np.testing.assert_array_equal(decoded[..., channel], mono)


def test_decode_raw_wrong_size():
    with pytest.raises(PayloadError) as error:
        decode_frame(bytes(17), RAW, raw_attachment(3, 2, "rgb8"))
    message = str(error.value)
    assert "18" in message and "17" in message
    assert "needs 18 bytes, got 17" in message


@pytest.mark.parametrize(
    "raw",
    [
        {},
        {"width": 3, "height": 2},
        {"width": 3, "format": "rgb8"},
        {"height": 2, "format": "rgb8"},
    ],
)
def test_decode_raw_without_layout(raw):
    attachment = parse_attachment(frame_attachment(0, 0.0, **raw))
    with pytest.raises(PayloadError, match="width, height and format"):
        decode_frame(bytes(18), RAW, attachment)


@pytest.mark.parametrize("payload", [b"", b"not a jpeg at all", b"\xff\xd8\xff" + bytes(50)])
def test_decode_jpeg_garbage(payload):
    with pytest.raises(PayloadError, match="does not decode"):
        decode_frame(payload, JPEG, parse_attachment(frame_attachment(0, 0.0)))


@pytest.mark.parametrize(
    ("height", "width", "taken"),
    [
        (32, 32, True),  # the smallest frame taken
        (60, 80, True),  # a small thermal camera's
        (1, 1, False),  # a placeholder, the walkthrough's bad frame
        (360, 31, False),  # one side under the minimum is enough
        (31, 480, False),
    ],
)
def test_check_frame_size(height, width, taken):
    image = np.zeros((height, width, 3), dtype=np.uint8)
    if taken:
        check_frame_size(image)
    else:
        with pytest.raises(PayloadError, match=f"a frame size of {width}x{height} is too small"):
            check_frame_size(image)


# -- payloads: detections ----------------------------------------------------------------------


def test_parse_detections_valid():
    body = json.dumps(
        {
            "sequence": 5,
            "detections": [
                {"x": 1, "y": 2, "w": 30, "h": 60, "score": 0.8},
                {"x": -4.5, "y": 0, "w": 10, "h": 20, "score": 2.5},
            ],
        }
    ).encode()
    message = parse_detections(body)
    assert message.sequence == 5
    assert [d.score for d in message.detections] == [0.8, 2.5]
    assert parse_detections(b'{"sequence": 0, "detections": []}').detections == []


@pytest.mark.parametrize(
    "body",
    [
        b"",
        b"[]",
        b"{oops",
        b'{"detections": []}',
        b'{"sequence": -1, "detections": []}',
        b'{"sequence": 1, "detections": [{"x": 0, "y": 0, "w": 0, "h": 5, "score": 1}]}',
        b'{"sequence": 1, "detections": [{"x": 0, "y": 0, "w": 5, "h": 5}]}',
        b'{"sequence": 1, "detections": [], "extra": 1}',
    ],
)
def test_parse_detections_invalid(body):
    with pytest.raises(PayloadError, match="bad detections message"):
        parse_detections(body)


def test_to_detections():
    message = UpstreamDetections(
        sequence=3,
        detections=[
            UpstreamDetection(x=1, y=2, w=30, h=60, score=0.8),
            UpstreamDetection(x=-4.5, y=0, w=10, h=20, score=2.5),
            UpstreamDetection(x=100, y=50, w=5, h=9, score=-1.0),
        ],
    )
    detections = to_detections(message)
    assert isinstance(detections, Detections)
    np.testing.assert_array_equal(
        detections.boxes, [[1, 2, 30, 60], [-4.5, 0, 10, 20], [100, 50, 5, 9]]
    )
    np.testing.assert_allclose(detections.probabilities, [0.8, 1.0, 0.0])
    assert np.all((detections.probabilities >= 0) & (detections.probabilities <= 1))
    empty = to_detections(UpstreamDetections(sequence=0, detections=[]))
    assert len(empty) == 0 and empty.boxes.shape == (0, 4)


# -- worker: LatestFrame -----------------------------------------------------------------------


def incoming(sequence: int) -> Incoming:
    attachment = FrameAttachment(sequence=sequence, timestamp=float(sequence))
    return Incoming(b"x", JPEG, attachment, time.perf_counter())


def test_latest_frame_keeps_the_newest():
    slot = LatestFrame()
    for sequence in range(3):
        slot.offer(incoming(sequence))
    taken = slot.take(timeout=0.1)
    assert taken is not None and taken.attachment.sequence == 2
    assert slot.skipped == 2
    assert slot.take(timeout=0.01) is None
    slot.offer(incoming(3))  # the slot is empty again: nothing more is skipped
    assert slot.take(timeout=0.1).attachment.sequence == 3
    assert slot.skipped == 2


def test_latest_frame_counts_the_frames_skipped_before_the_one_taken():
    # a tracks message says how many frames came between the previous one's and its own
    slot = LatestFrame()
    for sequence in range(3):
        slot.offer(incoming(sequence))
    assert slot.take(timeout=0.1).attachment.sequence == 2
    for sequence in range(3, 6):  # while frame 2 is tracked, 3 and 4 are replaced
        slot.offer(incoming(sequence))
    assert slot.skipped_before_taken == 2  # 0 and 1, skipped before frame 2
    assert slot.take(timeout=0.1).attachment.sequence == 5
    assert slot.skipped_before_taken == slot.skipped == 4  # with 3 and 4, before frame 5


def test_latest_frame_take_times_out():
    slot = LatestFrame()
    started = time.perf_counter()
    assert slot.take(timeout=0.2) is None
    elapsed = time.perf_counter() - started
    assert 0.18 <= elapsed < 1.0


def test_latest_frame_offer_wakes_a_waiting_take():
    slot = LatestFrame()
    taken: list[tuple[Incoming | None, float]] = []

    def consumer() -> None:
        frame = slot.take(timeout=5.0)
        taken.append((frame, time.perf_counter()))

    thread = threading.Thread(target=consumer)
    thread.start()
    time.sleep(0.05)  # let the consumer block
    offered = time.perf_counter()
    slot.offer(incoming(9))
    thread.join(timeout=5.0)
    assert not thread.is_alive()
    frame, woke = taken[0]
    assert frame is not None and frame.attachment.sequence == 9
    assert woke - offered < 0.5
    assert slot.skipped == 0


# -- worker: UpstreamBuffer --------------------------------------------------------------------


def some_detections(x: float = 0.0) -> Detections:
    return detections_from_arrays([[x, 0.0, 10.0, 20.0]], [0.9])


def test_upstream_take_returns_and_removes():
    buffer = UpstreamBuffer()
    assert not buffer.active()
    first, second = some_detections(1.0), some_detections(2.0)
    buffer.offer(4, first)
    buffer.offer(5, second)
    assert buffer.active()
    assert buffer.received == 2
    assert buffer.take(5, wait=0.0) is second
    assert buffer.take(4, wait=0.0) is first
    assert buffer.take(4, wait=0.0) is None


def test_upstream_take_waits_then_gives_up():
    buffer = UpstreamBuffer()
    buffer.offer(1, some_detections())
    started = time.perf_counter()
    assert buffer.take(2, wait=0.2) is None
    elapsed = time.perf_counter() - started
    assert 0.18 <= elapsed < 1.0
    assert buffer.take(1, wait=0.0) is not None  # the other sequence is still there


def test_upstream_take_gets_detections_that_arrive_while_waiting():
    buffer = UpstreamBuffer()
    expected = some_detections(7.0)

    def late_detector() -> None:
        time.sleep(0.05)
        buffer.offer(3, some_detections(6.0))  # another frame's: take keeps waiting
        time.sleep(0.05)
        buffer.offer(4, expected)

    thread = threading.Thread(target=late_detector)
    started = time.perf_counter()
    thread.start()
    try:
        got = buffer.take(4, wait=5.0)
    finally:
        thread.join(timeout=5.0)
    assert got is expected
    assert time.perf_counter() - started < 1.0
    assert buffer.take(3, wait=0.0) is not None


def test_upstream_capacity_drops_the_oldest():
    buffer = UpstreamBuffer(capacity=3)
    for sequence in range(5):
        buffer.offer(sequence, some_detections(float(sequence)))
    assert buffer.received == 5
    assert buffer.take(0, wait=0.0) is None
    assert buffer.take(1, wait=0.0) is None
    for sequence in (2, 3, 4):
        got = buffer.take(sequence, wait=0.0)
        assert got is not None and got.boxes[0, 0] == sequence


def test_upstream_forget_before_drops_only_what_arrived_earlier():
    # A camera that started over reuses sequence numbers: its previous run's detections go.
    buffer = UpstreamBuffer()
    buffer.offer(7, some_detections(1.0))
    buffer.offer(8, some_detections(2.0))
    restarted = time.perf_counter()
    buffer.offer(0, some_detections(3.0))  # the new run's first frame
    buffer.forget_before(restarted)
    assert buffer.take(7, wait=0.0) is None
    assert buffer.take(8, wait=0.0) is None
    assert buffer.take(0, wait=0.0).boxes[0, 0] == 3.0
    buffer.offer(7, some_detections(4.0))  # the new run's frame 7 is taken as usual
    assert buffer.take(7, wait=0.0).boxes[0, 0] == 4.0


def test_upstream_capacity_counts_a_reoffered_sequence_as_newest():
    buffer = UpstreamBuffer(capacity=2)
    buffer.offer(1, some_detections(1.0))
    buffer.offer(2, some_detections(2.0))
    buffer.offer(1, some_detections(10.0))  # replaces and becomes the newest
    buffer.offer(3, some_detections(3.0))  # drops 2, the oldest now
    assert buffer.take(2, wait=0.0) is None
    assert buffer.take(1, wait=0.0).boxes[0, 0] == 10.0
    assert buffer.take(3, wait=0.0) is not None


# -- keys --------------------------------------------------------------------------------------


def test_stream_keys():
    keys = StreamKeys("vtrack", "gate")
    assert keys.frames == "vtrack/cameras/gate/frames"
    assert keys.detections == "vtrack/cameras/gate/detections"
    assert keys.tracks == "vtrack/cameras/gate/tracks"
    assert keys.current == "vtrack/cameras/gate/tracks/current"
    assert keys.ended == "vtrack/cameras/gate/tracks/ended"
    assert keys.trackers == "vtrack/trackers/gate/*"
    assert keys.tracker_token("host-1") == "vtrack/trackers/gate/host-1"
    assert keys.as_dict() == {
        "frames": keys.frames,
        "detections": keys.detections,
        "tracks": keys.tracks,
        "ended": keys.ended,
        "current": keys.current,
        "trackers": keys.trackers,
    }
    # Every key is a valid Zenoh key expression, and the token matches the trackers wildcard.
    for key in [*keys.as_dict().values(), keys.tracker_token("host-1")]:
        zenoh.KeyExpr(key)
    assert zenoh.KeyExpr(keys.trackers).intersects(zenoh.KeyExpr(keys.tracker_token("x")))
    assert not zenoh.KeyExpr(keys.tracks).intersects(zenoh.KeyExpr(keys.current))


# -- session configuration ---------------------------------------------------------------------


def config_value(config: zenoh.Config, key: str):
    """``get_json`` answers with a JSON string (checked here once, so a change shows)."""
    text = config.get_json(key)
    assert isinstance(text, str)
    return json.loads(text)


def client_listens(config: zenoh.Config) -> list[str]:
    """What a client-mode session listens on: the default is per mode and has no client entry."""
    listen = config_value(config, "listen/endpoints")
    if isinstance(listen, dict):
        return listen.get("client") or []
    return listen


def test_hub_config_peer():
    options = ZenohOptions(listen=("tcp/0.0.0.0:7500",), connect=("tcp/10.0.0.1:7447",))
    config = options.hub_config()
    assert config_value(config, "mode") == "peer"
    assert config_value(config, "listen/endpoints") == ["tcp/0.0.0.0:7500"]
    assert config_value(config, "connect/endpoints") == ["tcp/10.0.0.1:7447"]
    assert config_value(config, "scouting/multicast/enabled") is False


def test_hub_config_defaults():
    config = ZenohOptions().hub_config()
    assert config_value(config, "mode") == "peer"
    assert config_value(config, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    assert config_value(config, "connect/endpoints") == []
    assert config_value(config, "scouting/multicast/enabled") is False


def test_member_config_peer():
    options = ZenohOptions(
        listen=("tcp/0.0.0.0:7500", "tcp/[::]:7501", "tcp/192.168.1.2:7502"),
        connect=("tcp/10.0.0.1:7447",),
    )
    config = options.member_config()
    assert config_value(config, "mode") == "peer"
    assert config_value(config, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    assert config_value(config, "connect/endpoints") == [
        "tcp/127.0.0.1:7500",
        "tcp/127.0.0.1:7501",
        "tcp/192.168.1.2:7502",
        "tcp/10.0.0.1:7447",
    ]
    assert config_value(config, "scouting/multicast/enabled") is False


def test_member_config_defaults_connect_to_the_default_hub():
    config = ZenohOptions().member_config()
    assert config_value(config, "connect/endpoints") == ["tcp/127.0.0.1:7447"]
    assert config_value(config, "listen/endpoints") == ["tcp/127.0.0.1:0"]


def test_client_mode_configs():
    options = ZenohOptions(
        mode="client", listen=("tcp/127.0.0.1:7500",), connect=("tcp/10.0.0.1:7447",)
    )
    for config in (options.hub_config(), options.member_config()):
        assert config_value(config, "mode") == "client"
        assert client_listens(config) == []
        assert config_value(config, "connect/endpoints") == ["tcp/10.0.0.1:7447"]
        assert config_value(config, "scouting/multicast/enabled") is False


def test_secured_configs_make_the_hub_a_router_and_the_members_its_clients(tmp_path):
    # In peer mode two peers can meet around the hub's rules; through a router they cannot.
    rules = AccessRules.from_maps("vtrack", "svc", {"cam": ["gate"]}, {})
    security = ZenohSecurity(
        TlsFiles(tmp_path / "s.pem", tmp_path / "s.key", tmp_path / "ca.pem"),
        user="svc",
        password="pw",
        users_file=tmp_path / "users.txt",
        access=rules,
    )
    options = ZenohOptions(listen=("tls/127.0.0.1:7500",), security=security)
    hub, member = options.hub_config(), options.member_config()
    assert config_value(hub, "mode") == "router" and config_value(member, "mode") == "client"
    assert client_listens(member) == []
    assert config_value(member, "connect/endpoints") == ["tls/127.0.0.1:7500"]
    assert config_value(hub, "transport/link/tls/listen_certificate") == str(tmp_path / "s.pem")
    assert config_value(member, "transport/link/tls/listen_certificate") is None
    assert config_value(member, "transport/link/tls/root_ca_certificate") == str(
        tmp_path / "ca.pem"
    )
    assert config_value(hub, "transport/auth/usrpwd/dictionary_file") == str(tmp_path / "users.txt")
    assert config_value(member, "transport/auth/usrpwd/dictionary_file") is None
    assert config_value(member, "transport/auth/usrpwd/user") == "svc"
    assert config_value(hub, "access_control/enabled") is True
    assert config_value(member, "access_control/enabled") is False
    # a client of a separate router presents its credentials; the rules are the router's
    client = dataclasses.replace(options, mode="client", connect=("tls/10.0.0.1:7447",))
    assert config_value(client.hub_config(), "access_control/enabled") is False
    assert config_value(client.hub_config(), "mode") == "client"


def test_a_message_over_the_size_limit_is_dropped_and_the_link_stays():
    # Zenoh's default takes messages up to 1 GiB, put together in memory before any check
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hub = open_session(ZenohOptions(listen=(endpoint,), max_message_size=2**20).hub_config())
    member = open_session(ZenohOptions(listen=(endpoint,)).member_config())
    try:
        sizes: list[int] = []
        hub.declare_subscriber("limit/test", lambda sample: sizes.append(len(sample.payload)))
        assert wait_for_neighbour(member, 5)
        wait_for(lambda: member.put("limit/test", b"x") or sizes, 10, "the first message")
        member.put("limit/test", b"x" * 2**21)
        member.put("limit/test", b"x" * 200)
        wait_for(lambda: 200 in sizes, 10, "the message after the large one")
        assert 2**21 not in sizes
    finally:
        member.close()
        hub.close()


def test_open_session_on_a_busy_port():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        config = ZenohOptions(listen=(f"tcp/127.0.0.1:{port}",)).hub_config()
        with pytest.raises(ZenohUnavailable) as error:
            open_session(config)
    message = str(error.value)
    assert "address already in use" in message.lower() or "address in use" in message.lower()
    assert str(port) in message
    assert " at /" not in message  # Zenoh's source locations are cut off


# -- stream schemas ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "camera", ["", "a/b", "cam*", "cam#1", "$cam", "cam?", "gate 1", " gate", "-gate", "x" * 65]
)
def test_stream_spec_rejects_bad_camera_names(camera):
    with pytest.raises(ValidationError):
        StreamSpec(camera=camera)


@pytest.mark.parametrize("camera", ["gate-1", "cam_2.north", "g", "A9", "x" * 64])
def test_stream_spec_accepts_camera_names(camera):
    spec = StreamSpec(camera=camera)
    assert spec.camera == camera
    zenoh.KeyExpr(StreamKeys("vtrack", camera).frames)


def test_stream_spec_rejects_unknown_fields():
    with pytest.raises(ValidationError, match="extra"):
        StreamSpec.model_validate({"camera": "gate", "fps": 10})


def test_stream_tracks_message_round_trip():
    assert issubclass(StreamTracksMessage, FrameTracksMessage)
    message = StreamTracksMessage.model_validate(
        {
            "frame_index": 3,
            "timestamp": 1700000000.5,
            "tracks": [
                {
                    "track_id": 2,
                    "box": {"x": 1.5, "y": 2.0, "w": 30.0, "h": 60.0},
                    "score": 0.75,
                    "occluded": False,
                }
            ],
            "camera": "gate",
            "sequence": 17,
            "latency": 0.012,
            "frames_skipped": 1,
            "detections": "upstream",
        }
    )
    again = StreamTracksMessage.model_validate_json(message.model_dump_json())
    assert again == message
    assert again.tracks[0].box.w == 30.0
    with pytest.raises(ValidationError):
        StreamTracksMessage.model_validate({**message.model_dump(), "unknown": 1})


# -- a real Zenoh round trip -------------------------------------------------------------------


def wait_until(condition, timeout: float, what: str, state=lambda: "") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what} {state()}")
        time.sleep(0.02)


PROBE = b"probe"


def test_publish_frames_round_trip():
    options = ZenohOptions(listen=(f"tcp/127.0.0.1:{free_port()}",))
    keys = StreamKeys("vtrack-test", "gate")
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, size=(24, 32, 3), dtype=np.uint8) for _ in range(3)]
    boxes = [[10.0 * (i + 1), 4.0, 8.0, 16.0] for i in range(3)]

    def detections(index: int) -> Detections:
        return detections_from_arrays([boxes[index]], [0.5 + 0.1 * index])

    lock = threading.Lock()
    got_frames: list[tuple[bytes, str, bytes | None]] = []
    got_detections: list[bytes] = []
    probed: set[str] = set()

    def on_frame(sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
        with lock:
            if payload == PROBE:
                probed.add("frames")
            else:
                got_frames.append((payload, str(sample.encoding), attachment))

    def on_detections(sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        with lock:
            if payload == PROBE:
                probed.add("detections")
            else:
                got_detections.append(payload)

    hub = open_session(options.hub_config())
    receiver = sender = None
    try:
        receiver = tools.member_session(options)
        sender = tools.member_session(options)
        subscribers = (
            receiver.declare_subscriber(keys.frames, on_frame),
            receiver.declare_subscriber(keys.detections, on_detections),
        )
        # Gossip connects the two members (each connects only to the hub) in a fraction of a
        # second, and for a few more milliseconds samples can still be lost even though the
        # sender's publishers already match the receiver's subscribers. So: probe both keys
        # until the receiver has heard on each, then publish.
        deadline = time.monotonic() + 5.0
        while True:
            with lock:
                if probed == {"frames", "detections"}:
                    break
            if time.monotonic() > deadline:
                pytest.fail(f"the members did not connect in 5 s (heard on {sorted(probed)})")
            sender.put(keys.frames, PROBE)
            sender.put(keys.detections, PROBE)
            time.sleep(0.02)

        # a network camera's frame carries the time it was taken (CaptureClock)
        taken = time.time() + 100.0
        items = [*frames[:2], Captured(frames[2], taken)]
        report = tools.publish_frames(
            sender,
            keys,
            iter(items),
            None,
            detections=detections,
            detections_scale=0.5,
            first_sequence=10,
        )
        assert report.frames == 3 and report.late == 0

        def all_arrived() -> bool:
            with lock:
                return len(got_frames) >= 3 and len(got_detections) >= 3

        wait_until(
            all_arrived,
            5.0,
            "3 frames and 3 detections messages",
            lambda: f"got {len(got_frames)} frames and {len(got_detections)} detections",
        )
        time.sleep(0.05)  # nothing more comes
        for subscriber in subscribers:
            subscriber.undeclare()
    finally:
        for session in (sender, receiver, hub):
            if session is not None:
                session.close()

    assert len(got_frames) == 3 and len(got_detections) == 3
    for index, (payload, encoding, attachment_bytes) in enumerate(got_frames):
        attachment = parse_attachment(attachment_bytes)
        assert attachment.sequence == 10 + index
        assert attachment.timestamp > 1e9  # Unix time
        assert encoding == "image/jpeg"
        assert encoding == str(zenoh.Encoding.IMAGE_JPEG)
        image = decode_frame(payload, encoding, attachment)
        assert image.shape == frames[index].shape
    stamps = [parse_attachment(a).timestamp for _, _, a in got_frames]
    assert stamps == sorted(stamps)
    assert stamps[2] == taken and stamps[1] < taken - 99  # the others: when they were sent

    messages = [parse_detections(body) for body in got_detections]
    assert [m.sequence for m in messages] == [10, 11, 12]
    for index, message in enumerate(messages):
        (item,) = message.detections
        assert [item.x, item.y, item.w, item.h] == pytest.approx([b * 0.5 for b in boxes[index]])
        assert item.score == pytest.approx(0.5 + 0.1 * index)
        np.testing.assert_allclose(to_detections(message).boxes, [[b * 0.5 for b in boxes[index]]])


# -- store ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "spec", [{"record_keep": 3}, {"record": False, "record_segment": 60}, {"record_images": "jpeg"}]
)
def test_recording_options_without_record_are_refused_but_stored_ones_still_read(tmp_path, spec):
    with pytest.raises(ValidationError, match="only with record: true"):
        StreamSpec.model_validate({"camera": "gate", **spec})
    # a stream an earlier version accepted with them still lists and starts
    store = StreamStore(tmp_path / "jobs.db")
    try:
        # written as an earlier version did (model_copy does not validate)
        store.put(StreamSpec(camera="gate").model_copy(update=spec))
        [record] = store.all()
        assert record.spec.camera == "gate" and not record.spec.record
    finally:
        store.close()
    assert StreamSpec.model_validate({"camera": "gate", **spec, "record": True}).record


def test_track_id_reservations_only_go_up_and_outlive_the_stream(tmp_path):
    store = StreamStore(tmp_path / "jobs.db")
    try:
        assert store.reserved_track_ids("gate") == 0  # never tracked: ids start at 1
        store.reserve_track_ids("gate", 100)
        store.reserve_track_ids("gate", 40)  # a late, lower write does not take ids back
        store.reserve_track_ids("hall", 7)
        spec = StreamSpec(camera="gate")
        store.put(spec)
        store.delete("gate")
    finally:
        store.close()
    reopened = StreamStore(tmp_path / "jobs.db")  # a worker's own connection, or the next run
    try:
        assert reopened.reserved_track_ids("gate") == 100
        assert reopened.reserved_track_ids("hall") == 7
    finally:
        reopened.close()


def test_a_liveliness_token_on_a_wildcard_is_no_tracker():
    # before: one token on vtrack-test/trackers/*/0 answered every camera's query, and every
    # service put its streams on standby and refused new ones (409)
    options = ZenohOptions(listen=(f"tcp/127.0.0.1:{free_port()}",))
    keys = StreamKeys("vtrack-test", "gate")
    hub = open_session(options.hub_config())
    try:
        forged = hub.liveliness().declare_token("vtrack-test/trackers/*/0")
        real = hub.liveliness().declare_token(keys.tracker_token("a1b2"))
        seen: list[tuple[str, bool]] = []
        watcher = tools.watch_trackers(hub, keys, lambda i, alive: seen.append((i, alive)))
        assert tools.trackers_of(hub, keys) == ["a1b2"]
        real.undeclare()
        wait_until(lambda: ("a1b2", False) in seen, 5, "the token to go")
        assert seen == [("a1b2", True), ("a1b2", False)]
        watcher.undeclare()
        forged.undeclare()
    finally:
        hub.close()
