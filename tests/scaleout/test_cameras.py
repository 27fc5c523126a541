"""Cameras spread over two instances of one database (issue 79): real services on one Zenoh
network, a real PostgreSQL server. Each camera is tracked by the instance it hashes to, by
exactly one; when an instance is killed its cameras move to the other."""

from __future__ import annotations

import json
import signal
import time
import uuid

import psycopg
import pytest

from devtools.testing import Server, free_port, wait_for
from service.streams.keys import StreamKeys
from service.streams.manager import _owner_of
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, trackers_of

pytestmark = pytest.mark.scaleout

MOVE_SECONDS = 30.0
"""The longest a camera of a killed instance may go untracked (docs/service.md says what it
takes: the token's loss, two looks of the arbiter, a worker's start)."""


def cameras_split(count: int) -> list[str]:
    """``count`` camera names that rendezvous hashing gives to both instances."""
    names = [f"cam{index}" for index in range(50)]
    for start in range(len(names) - count):
        chosen = names[start : start + count]
        if {_owner_of(camera, ["a", "b"]) for camera in chosen} == {"a", "b"}:
            return chosen
    raise AssertionError("no split")  # pragma: no cover - 50 names always split


def trackers(servers: dict[str, Server], camera: str) -> set[str]:
    """The instances whose stream of ``camera`` runs a worker (not standing by)."""
    found = set()
    for name, server in servers.items():
        if server.process is None or server.process.poll() is not None:
            continue
        with server.client() as client:
            status = client.get(f"/v1/streams/{camera}")
        if status.status_code == 200 and status.json()["state"] in ("waiting", "running"):
            found.add(name)
    return found


def test_cameras_are_spread_and_move_when_an_instance_dies(postgres, tmp_path):
    name = f"jobs_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres.url, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    url = postgres.url.rsplit("/", 1)[0] + f"/{name}"
    hub = f"tcp/127.0.0.1:{free_port()}"
    common = {"database_url": url, "workers": 1}
    servers = {
        "a": Server(tmp_path / "data", name="a", instance_name="a", **common,
                    zenoh_listen=json.dumps([hub])),
        "b": Server(tmp_path / "data", name="b", instance_name="b", **common,
                    zenoh_listen=json.dumps([f"tcp/127.0.0.1:{free_port()}"]),
                    zenoh_connect=json.dumps([hub])),
    }  # fmt: skip
    cameras = cameras_split(3)
    try:
        for server in servers.values():
            server.start()
        with servers["a"].client() as client:
            for camera in cameras:
                response = client.post("/v1/streams", json={"camera": camera})
                assert response.status_code == 201, response.text
        owners = {camera: _owner_of(camera, ["a", "b"]) for camera in cameras}
        for camera in cameras:
            wait_for(lambda c=camera: trackers(servers, c) == {owners[c]}, 60, f"{camera}")
        watcher = member_session(ZenohOptions(listen=(hub,)))
        try:
            for camera in cameras:  # one tracker token each, over Zenoh too
                keys = StreamKeys("vtrack", camera)
                wait_for(lambda k=keys: len(trackers_of(watcher, k)) == 1, 30, "one token")
            servers["b"].process.send_signal(signal.SIGKILL)
            servers["b"].process.wait(10)
            killed = time.monotonic()
            for camera in cameras:
                wait_for(lambda c=camera: trackers(servers, c) == {"a"}, MOVE_SECONDS, camera)
            moved = time.monotonic() - killed
            for camera in cameras:
                keys = StreamKeys("vtrack", camera)
                wait_for(lambda k=keys: len(trackers_of(watcher, k)) == 1, 30, "one token")
        finally:
            watcher.close()
        assert moved < MOVE_SECONDS
        log = servers["a"].log()
        assert all(f"stream {c}: worker" in log for c in cameras if owners[c] == "b")
    finally:
        for server in servers.values():
            server.stop()
