"""The publish and watch tools (service.streams.tools) over a real Zenoh session: frames
and detections round trip, trackers seen by their liveliness tokens."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
import zenoh

from devtools.testing import free_port, wait_for
from service.streams import tools
from service.streams.capture_clock import Captured
from service.streams.keys import StreamKeys
from service.streams.payloads import (
    decode_frame,
    parse_attachment,
    parse_detections,
    to_detections,
)
from service.streams.session import (
    ZenohOptions,
    open_session,
)
from tracking.detection.base import Detections
from tracking.detection.external import detections_from_arrays

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
        def connected() -> bool:
            with lock:
                if probed == {"frames", "detections"}:
                    return True
            sender.put(keys.frames, PROBE)
            sender.put(keys.detections, PROBE)
            return False

        wait_for(connected, 5.0, "the members to connect (a probe heard on each key)", 0.02)

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

        wait_for(all_arrived, 5.0, "3 frames and 3 detections messages", 0.02)
        time.sleep(0.05)  # a pause, not a condition: nothing more comes, as checked below
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
        wait_for(lambda: ("a1b2", False) in seen, 5, "the token to go", 0.02)
        assert seen == [("a1b2", True), ("a1b2", False)]
        watcher.undeclare()
        forged.undeclare()
    finally:
        hub.close()
