"""Fixtures of the live-stream tests: one ``vtrack serve`` per test module, this process's Zenoh
session to it, and the PETS frames and detections the cameras publish."""

from __future__ import annotations

from itertools import islice

import numpy as np
import pytest
import zenoh

from service.streams.session import ZenohOptions
from service.streams.tools import member_session, video_frames
from tests.service.conftest import PETS_VIDEO, Server
from tracking.detection import MotDetections


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> Server:
    """One service for the module's tests; each test tracks its own camera."""
    folder = tmp_path_factory.mktemp("streams")
    server = Server(folder / "data", workers=1).start()
    yield server
    server.stop()


@pytest.fixture(scope="module")
def session(server) -> zenoh.Session:
    """This process's Zenoh session: the cameras and consumers of the tests."""
    session = member_session(ZenohOptions(listen=server.zenoh_listen))
    yield session
    session.close()


@pytest.fixture(scope="module")
def pets_frames(shared_data) -> list[np.ndarray]:
    frames, _ = video_frames(str(shared_data / PETS_VIDEO))
    return list(islice(frames, 60))


@pytest.fixture(scope="module")
def public_detections(shared_data) -> MotDetections:
    """The public detections of PETS09-S2L1 (768x576: ``live.PUBLIC_SCALE`` to the video)."""
    return MotDetections.from_file(shared_data / "mot" / "PETS09-S2L1" / "det" / "det.txt")
