"""Helpers of the live-stream tests: a consumer in this process, a stream started and awaited
through the API, its status, and the stderr of a tool running in its own process."""

from __future__ import annotations

import subprocess
import sys
import threading

import httpx
import zenoh

from api_schemas.streams import StreamTracksMessage
from service.streams.keys import StreamKeys
from service.streams.tools import follow_tracks, reach_tracker, trackers_of
from tests.service.conftest import wait_for

VTRACK = [sys.executable, "-m", "service.cli"]


class Follower:
    """A consumer of one camera's tracks, in this process."""

    def __init__(self, session: zenoh.Session, keys: StreamKeys) -> None:
        self.messages: list[tuple[StreamTracksMessage, float]] = []
        self._lock = threading.Lock()
        self._subscriber = follow_tracks(session, keys, self._received)

    def _received(self, message: StreamTracksMessage, arrived: float) -> None:
        with self._lock:
            self.messages.append((message, arrived))

    def received(self) -> list[StreamTracksMessage]:
        with self._lock:
            return [m for m, _ in self.messages]

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


class StderrLines:
    """The stderr lines of a running process, gathered by a thread as they come."""

    def __init__(self, process: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self._process = process
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self._process.stderr:
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
