"""Fixtures for the service tests: short cuts of the PETS video and real servers on loopback.

Servers run as users run them: ``python -m service.cli serve`` in a subprocess on a free
127.0.0.1 port, with settings from ``VTRACK_*`` environment variables. Waits poll for a
condition with a deadline; nothing sleeps for a fixed time hoping something has happened.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import httpx
import pytest

from tests.conftest import REPO_ROOT

PETS_VIDEO = Path("video") / "pets09_s2l1_480x360.avi"
FAST_OPTIONS = {"formats": ["json"]}


def cut_video(source: Path, target: Path, frames: int, start: int = 0) -> Path:
    """The first ``frames`` frames (from ``start``) of ``source`` as an MJPG AVI at its rate."""
    capture = cv2.VideoCapture(str(source))
    fps = capture.get(cv2.CAP_PROP_FPS) or 10.0
    writer = None
    try:
        for index in range(start + frames):
            ok, frame = capture.read()
            if not ok:
                raise RuntimeError(f"{source} has fewer than {start + frames} frames")
            if index < start:
                continue
            if writer is None:
                size = (frame.shape[1], frame.shape[0])
                writer = cv2.VideoWriter(str(target), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
            writer.write(frame)
    finally:
        capture.release()
        if writer is not None:
            writer.release()
    return target


@pytest.fixture(scope="session")
def pets_cut(shared_data, tmp_path_factory) -> Path:
    """24 frames (2.4 s) of PETS09-S2L1 where people walk through the middle of the scene."""
    folder = tmp_path_factory.mktemp("pets")
    return cut_video(shared_data / PETS_VIDEO, folder / "pets_24.avi", 24)


@pytest.fixture(scope="session")
def pets_short(shared_data, tmp_path_factory) -> Path:
    """8 frames of the same: for jobs whose content does not matter."""
    folder = tmp_path_factory.mktemp("pets")
    return cut_video(shared_data / PETS_VIDEO, folder / "pets_8.avi", 8)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def wait_for(
    condition: Callable[[], object], timeout: float, what: str, interval: float = 0.1
) -> object:
    """Poll ``condition`` until it returns something truthy; fail after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


class Server:
    """``vtrack serve`` in a subprocess on a loopback port."""

    def __init__(self, data_dir: Path, workers: int = 2, **settings: object) -> None:
        self.data_dir = data_dir
        self.workers = workers
        self.settings = settings
        self.process: subprocess.Popen | None = None
        self.port = 0
        self.log_path = data_dir.parent / f"{data_dir.name}-server.log"
        self.token = settings.get("api_token")

    @property
    def zenoh_listen(self) -> tuple[str, ...]:
        return tuple(json.loads(self.settings["zenoh_listen"]))

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def client(self, token: str | None = None, **kwargs) -> httpx.Client:
        token = token if token is not None else self.token
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30.0, **kwargs)

    def start(self, timeout: float = 60.0) -> Server:
        self.port = free_port()
        env = {k: v for k, v in os.environ.items() if not k.startswith("VTRACK_")}
        # Each server gets its own Zenoh port, so that servers of parallel tests never meet.
        self.settings.setdefault("zenoh_listen", json.dumps([f"tcp/127.0.0.1:{free_port()}"]))
        env.update({f"VTRACK_{k.upper()}": str(v) for k, v in self.settings.items()})
        command = [
            sys.executable,
            "-m",
            "service.cli",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--workers",
            str(self.workers),
            "--data-dir",
            str(self.data_dir),
            "--log-level",
            "info",
        ]
        log = self.log_path.open("a")
        self.process = subprocess.Popen(
            command, cwd=REPO_ROOT, env=env, stdout=log, stderr=subprocess.STDOUT
        )
        log.close()
        wait_for(self._ready, timeout, f"the server on port {self.port} to be ready")
        return self

    def _ready(self) -> bool:
        if self.process is not None and self.process.poll() is not None:
            raise AssertionError(f"the server exited early:\n{self.log()}")
        try:
            return httpx.get(f"{self.url}/readyz", timeout=2.0).status_code == 200
        except httpx.TransportError:
            return False

    def log(self) -> str:
        return self.log_path.read_text() if self.log_path.is_file() else ""

    def stop(self) -> None:
        """A clean stop (SIGTERM), as a service manager does."""
        if self.process is None or self.process.poll() is not None:
            return
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10)

    def kill(self) -> None:
        """The service dies (SIGKILL): no shutdown code runs."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)


@pytest.fixture
def make_server(tmp_path) -> Iterator[Callable[..., Server]]:
    """Start servers for one test; all are stopped after it."""
    servers: list[Server] = []

    def make(data_dir: Path | None = None, **kwargs) -> Server:
        server = Server(data_dir or tmp_path / f"data{len(servers)}", **kwargs)
        servers.append(server)
        return server.start()

    yield make
    for server in servers:
        server.stop()


def submit(
    client: httpx.Client, video: Path, options: dict | None = None, filename: str | None = None
) -> httpx.Response:
    files = {"video": (filename or video.name, video.read_bytes(), "video/x-msvideo")}
    data = {"options": json.dumps(options)} if options is not None else None
    return client.post("/v1/jobs", files=files, data=data)


def wait_for_state(
    client: httpx.Client, job_id: str, states: tuple[str, ...], timeout: float = 120.0
) -> dict:
    def reached():
        status = client.get(f"/v1/jobs/{job_id}").json()
        return status if status["state"] in states else None

    return wait_for(reached, timeout, f"job {job_id} to reach {states}", interval=0.2)


def wait_for_frames(client: httpx.Client, job_id: str, frames: int, timeout: float = 60.0) -> dict:
    """Until the job is running and has read at least ``frames`` frames."""

    def reached():
        status = client.get(f"/v1/jobs/{job_id}").json()
        assert status["state"] in ("queued", "running"), status
        running = status["state"] == "running"
        return status if running and status["progress"]["frames_done"] >= frames else None

    return wait_for(reached, timeout, f"job {job_id} to pass frame {frames}", interval=0.05)


def schema_for(name: str) -> dict:
    """A JSON Schema validating one public model, from the exported file."""
    document = json.loads((REPO_ROOT / "api_schemas" / "schema.json").read_text())
    return {"$defs": document["$defs"], "$ref": f"#/$defs/{name}"}
