"""Helpers of the live-stream tests: a consumer in this process, a stream started and awaited
through the API, its status, and the output of a tool running in its own process."""

from __future__ import annotations

import contextlib
import itertools
import subprocess
import sys
import threading
from collections.abc import Iterator

import httpx
import numpy as np
import zenoh

from api_schemas.streams import StreamTracksEnded, StreamTracksMessage
from service.streams.keys import StreamKeys
from service.streams.tools import follow_tracks, publish_frames, reach_tracker, trackers_of
from tests.service.conftest import wait_for
from tracking.detection import MotDetections

VTRACK = [sys.executable, "-m", "service.cli"]
# The public detections of PETS09-S2L1 are boxes on its 768x576 frames; the video is 480x360.
PUBLIC_SCALE = 0.625


class Follower:
    """A consumer of one camera's tracks, and of the news that they ended, in this process."""

    def __init__(self, session: zenoh.Session, keys: StreamKeys) -> None:
        self.messages: list[tuple[StreamTracksMessage, float]] = []
        self._endings: list[StreamTracksEnded] = []
        self._lock = threading.Lock()
        self._subscriber = follow_tracks(session, keys, self._received, self._ended)

    def _received(self, message: StreamTracksMessage, arrived: float) -> None:
        with self._lock:
            self.messages.append((message, arrived))

    def _ended(self, message: StreamTracksEnded, arrived: float) -> None:
        with self._lock:
            self._endings.append(message)

    def received(self) -> list[StreamTracksMessage]:
        with self._lock:
            return [m for m, _ in self.messages]

    def endings(self) -> list[StreamTracksEnded]:
        with self._lock:
            return list(self._endings)

    def close(self) -> None:
        self._subscriber.undeclare()


def start_stream(client: httpx.Client, session: zenoh.Session, camera: str, **spec) -> dict:
    """POST the stream and wait until its worker listens and this session can reach it."""
    response = client.post("/v1/streams", json={"camera": camera, **spec})
    assert response.status_code == 201, response.text
    keys = StreamKeys("vtrack", camera)

    wait_for(
        lambda: client.get(f"/v1/streams/{camera}").json()["state"] == "waiting",
        60,
        f"stream {camera} to listen",
    )
    assert reach_tracker(session, keys, timeout=30), f"the tracker of {camera} does not answer"
    assert trackers_of(session, keys), "no liveliness token for a running stream"
    return response.json()


def status(client: httpx.Client, camera: str) -> dict:
    response = client.get(f"/v1/streams/{camera}")
    assert response.status_code == 200, response.text
    return response.json()


def all_taken(client: httpx.Client, camera: str, frames: int) -> dict:
    """The stream's counters once ``frames`` frames came in and each was processed, skipped or
    refused as malformed."""

    def taken():
        counters = status(client, camera)["counters"]
        done = counters["frames_processed"] + counters["frames_skipped"] + counters["malformed"]
        return counters["frames_in"] == frames == done and counters

    return wait_for(taken, 60, f"all {frames} frames of {camera} to be taken")


def put_frame(session, keys, payload: bytes, attachment: bytes | None, encoding) -> None:
    session.put(keys.frames, payload, encoding=encoding, attachment=attachment)


class OutputLines:
    """The lines a running process writes to its stderr (or stdout), gathered by a thread."""

    def __init__(self, process: subprocess.Popen, stream: str = "stderr") -> None:
        self.lines: list[str] = []
        self._process = process
        self._stream = getattr(process, stream)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self._stream:
            self.lines.append(line)

    def has(self, text: str) -> bool:
        """Whether a line so far holds ``text``; a process that ended without one fails."""
        if any(text in line for line in list(self.lines)):
            return True
        if self._process.poll() is not None:
            self._reader.join(5)
            assert any(text in line for line in self.lines), "".join(self.lines)
            return True
        return False


@contextlib.contextmanager
def camera_running(
    session: zenoh.Session,
    keys: StreamKeys,
    frames: list[np.ndarray],
    public: MotDetections | None = None,
    *,
    block: bool = False,
) -> Iterator[None]:
    """A camera publishing ``frames`` over and over at 10 fps until the block ends: with
    ``public``, the public detections as its upstream detector's (so that tracking is cheap);
    with ``block``, every frame reaches the tracker (:func:`publish_frames`)."""
    stop = threading.Event()
    count = len(frames)
    detections = None if public is None else (lambda index: public.for_frame(index % count))
    thread = threading.Thread(
        target=publish_frames,
        args=(session, keys, itertools.cycle(frames), 10.0),
        kwargs={
            "detections": detections,
            "detections_scale": PUBLIC_SCALE,
            "stop": stop,
            "block": block,
        },
        daemon=True,
    )
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(10)
