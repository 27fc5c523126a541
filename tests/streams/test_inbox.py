"""The worker's inbox (service.streams.inbox): the one-frame slot that keeps the newest
frame, and the buffer of upstream detections waiting for their frame."""

from __future__ import annotations

import threading
import time

from api_schemas.streams import (
    FrameAttachment,
)
from service.streams.inbox import Incoming, LatestFrame, UpstreamBuffer
from service.streams.payloads import (
    JPEG,
)
from tracking.detection.base import Detections
from tracking.detection.external import detections_from_arrays

# -- LatestFrame -------------------------------------------------------------------------------


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
    # a pause, not a condition: the take's waiting cannot be seen from here, and an offer made
    # before it would pass too, testing less
    time.sleep(0.05)
    offered = time.perf_counter()
    slot.offer(incoming(9))
    thread.join(timeout=5.0)
    assert not thread.is_alive()
    frame, woke = taken[0]
    assert frame is not None and frame.attachment.sequence == 9
    assert woke - offered < 0.5
    assert slot.skipped == 0


# -- UpstreamBuffer ----------------------------------------------------------------------------


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
        # pauses that are the test: the detections arrive while the take waits
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
