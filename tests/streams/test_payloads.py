"""What travels on the stream keys (service.streams.payloads): frame attachments, frames
(JPEG, PNG, raw, H.264) and detections messages, each checked and refused with a reason."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from api_schemas.streams import (
    FrameAttachment,
    PixelFormat,
    UpstreamDetection,
    UpstreamDetections,
)
from devtools.simulated_cameras import access_units
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
from tracking.detection.base import Detections

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


# -- attachments -------------------------------------------------------------------------------


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


# -- frames ------------------------------------------------------------------------------------


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


# -- detections --------------------------------------------------------------------------------


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
