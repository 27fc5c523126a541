"""Fixtures for the service tests: short cuts of the PETS video and real servers on loopback.

Servers run as users run them: ``python -m service.cli serve`` in a subprocess on a free
127.0.0.1 port, with settings from ``VTRACK_*`` environment variables. Waits poll for a
condition with a deadline; nothing sleeps for a fixed time hoping something has happened.
"""

from __future__ import annotations

import fractions
import json
from collections.abc import Callable, Iterator
from itertools import islice
from pathlib import Path

import av
import httpx
import numpy as np
import pytest

from api_schemas.common import ERROR_STATUS, ErrorResponse, ErrorType
from devtools.clips import cut_video
from devtools.testing import Server, wait_for
from service.frames import open_frames
from tests.conftest import REPO_ROOT

PETS_VIDEO = Path("video") / "pets09_s2l1_480x360.avi"
# For jobs whose people do not matter: the embedded detector on the frames as they are, not
# enlarged twice as it enlarges 360-px video by default: a quarter of the CPU (8 against 36 s for
# 120 frames), since it then finds none of the clip's 40-55 px people and the tracker has little
# to do either.
FAST_OPTIONS = {"formats": ["json"], "detector": {"name": "default", "upscale": 1.0}}


@pytest.fixture(scope="session")
def long_video(shared_data, tmp_path_factory) -> Path:
    """150 frames: with ``FAST_OPTIONS``, a job that runs long enough to be caught mid-way
    (about 5 s of work on an idle machine)."""
    folder = tmp_path_factory.mktemp("pets")
    return cut_video(shared_data / PETS_VIDEO, folder / "pets_150.avi", 150)


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


# Presentation times in milliseconds of a video whose recorder dropped frames: steady 10 fps
# runs broken by gaps of 0.5 s and 1.2 s.
VFR_MS = [0, 100, 200, 300, 800, 900, 1000, 2200, 2300, 2400, 2500, 2600]


@pytest.fixture(scope="session")
def vfr_video(shared_data, tmp_path_factory):
    """An MPEG-4 file of real PETS frames stamped with ``VFR_MS``."""
    frames = list(islice(open_frames(shared_data / PETS_VIDEO), len(VFR_MS)))
    return write_stamped(frames, VFR_MS, tmp_path_factory.mktemp("vfr") / "dropped_frames.mp4")


def mux_silence(container, seconds: float) -> None:
    """Add a mono AAC track of ``seconds`` of silence to ``container`` (PyAV, open for writing;
    its other streams must be added before)."""
    audio = container.add_stream("aac", rate=48000)
    audio.layout = "mono"
    samples = 1024  # per AAC frame
    for start in range(0, round(seconds * 48000), samples):
        frame = av.AudioFrame.from_ndarray(
            np.zeros((1, samples), np.float32), format="fltp", layout="mono"
        )
        frame.sample_rate, frame.pts = 48000, start
        container.mux(audio.encode(frame))
    container.mux(audio.encode())


def write_stamped(frames, stamps_ms, path: Path, rate: int = 10) -> Path:
    """480x360 ``frames`` at presentation times ``stamps_ms`` in ``path``'s container (MPEG-4
    video stating ``rate`` frames per second; written by PyAV: OpenCV's writer has one rate)."""
    millisecond = fractions.Fraction(1, 1000)
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=rate)
        stream.width, stream.height, stream.pix_fmt = 480, 360, "yuv420p"
        stream.time_base = millisecond
        for image, ms in zip(frames, stamps_ms, strict=True):
            frame = av.VideoFrame.from_ndarray(image, format="rgb24")
            frame.pts, frame.time_base = ms, millisecond
            container.mux(stream.encode(frame))
        container.mux(stream.encode())
    return path


def write_gray(path: Path, width: int, height: int, frames: int = 2) -> Path:
    """``frames`` uniform gray frames of ``width`` x ``height`` (MPEG-4 in ``path``'s
    container): a large video in a few kilobytes."""
    with av.open(str(path), "w") as container:
        stream = container.add_stream("mpeg4", rate=10)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        for _ in range(frames):
            image = np.full((height, width, 3), 90, np.uint8)
            container.mux(stream.encode(av.VideoFrame.from_ndarray(image, format="rgb24")))
        container.mux(stream.encode())
    return path


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


def error_of(response: httpx.Response, type: str) -> dict:
    """The body of an error answer of ``type``, checked: an ErrorResponse of that type, with the
    type's status. Tests check the type, which programs read, rather than words of the sentence,
    which may be reworded (one test per type reads a whole sentence)."""
    assert response.headers.get("content-type", "").startswith("application/json"), response.text
    body = ErrorResponse.model_validate(response.json())
    assert (response.status_code, body.type) == (ERROR_STATUS[ErrorType(type)], type), response.text
    return response.json()


def metrics(client: httpx.Client) -> dict[str, float]:
    """The service's ``/metrics``: each sample's name (with its labels) and value."""
    lines = client.get("/metrics").text.splitlines()
    return {
        name: float(value)
        for name, value in (line.rsplit(" ", 1) for line in lines if line and line[0] != "#")
    }


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
