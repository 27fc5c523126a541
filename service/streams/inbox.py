"""What arrives from a camera, held for the tracking loop: the newest frame, and the upstream
detections of recent frames.

Zenoh delivers samples on its own threads; they are dropped here, and the tracking thread takes
them when it is ready. The frame slot holds one frame (a slow tracker skips frames instead of
queueing them: the frame tracked next is always the newest); detections wait, by frame sequence
number, for their frame.
"""

from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass

import numpy as np

from api_schemas.streams import FrameAttachment
from tracking.detection.base import Detections

UPSTREAM_ACTIVE = 5.0
"""Seconds after the last upstream detections message during which the camera counts as having
an upstream detector (and frames wait ``detections_wait`` for theirs)."""


@dataclass(slots=True)
class Incoming:
    """A frame sample as it arrived, attachment checked; ``image`` is already decoded for
    H.264 (every unit is decoded on arrival), else ``None``: decoded when taken."""

    payload: bytes
    encoding: str
    attachment: FrameAttachment
    arrived: float  # time.perf_counter()
    image: np.ndarray | None = None


class LatestFrame:
    """A one-frame slot: a new frame replaces an untaken one, which counts as skipped."""

    def __init__(self) -> None:
        self._ready = threading.Condition()
        self._frame: Incoming | None = None
        self.skipped = 0
        self.skipped_before_taken = 0  # of them, those before the frame taken last

    def offer(self, frame: Incoming) -> None:
        with self._ready:
            if self._frame is not None:
                self.skipped += 1
            self._frame = frame
            self._ready.notify()

    def take(self, timeout: float) -> Incoming | None:
        with self._ready:
            if self._frame is None:
                self._ready.wait(timeout)
            frame, self._frame = self._frame, None
            if frame is not None:  # those skipped later came after it
                self.skipped_before_taken = self.skipped
            return frame

    def count_skipped(self) -> None:
        """Count a frame the tracker took but did not track as skipped."""
        with self._ready:
            self.skipped += 1


class UpstreamBuffer:
    """Upstream detections by frame sequence number, the newest ``capacity`` kept."""

    def __init__(self, capacity: int = 256) -> None:
        self._arrived = threading.Condition()
        self._by_sequence: collections.OrderedDict[int, Detections] = collections.OrderedDict()
        self._arrived_at: dict[int, float] = {}  # time.perf_counter(), by sequence
        self._capacity = capacity
        self.last_seen: float | None = None  # time.monotonic()
        self.received = 0

    def offer(self, sequence: int, detections: Detections) -> None:
        with self._arrived:
            self._by_sequence[sequence] = detections
            self._by_sequence.move_to_end(sequence)
            self._arrived_at[sequence] = time.perf_counter()
            while len(self._by_sequence) > self._capacity:
                oldest, _ = self._by_sequence.popitem(last=False)
                self._arrived_at.pop(oldest, None)
            self.last_seen = time.monotonic()
            self.received += 1
            self._arrived.notify_all()

    def active(self) -> bool:
        seen = self.last_seen
        return seen is not None and time.monotonic() - seen < UPSTREAM_ACTIVE

    def take(self, sequence: int, wait: float) -> Detections | None:
        """The detections of frame ``sequence``, waiting up to ``wait`` s for them to arrive."""
        with self._arrived:
            self._arrived.wait_for(lambda: sequence in self._by_sequence, timeout=wait)
            self._arrived_at.pop(sequence, None)
            return self._by_sequence.pop(sequence, None)

    def forget_before(self, moment: float) -> None:
        """Drop the detections that arrived before ``moment`` (``time.perf_counter()``): after
        the camera started over, they belong to frames of its previous run whose sequence
        numbers the new run reuses."""
        with self._arrived:
            for sequence in [s for s, t in self._arrived_at.items() if t < moment]:
                del self._arrived_at[sequence]
                del self._by_sequence[sequence]
