"""Live streams through a service's life: streams from its settings across a restart, a
worker that keeps failing. Lifecycle only, no rates measured: not marked realtime, these run
beside other tests."""

from __future__ import annotations

import json
import os
import shutil
import signal

import pytest

from service.streams.keys import StreamKeys
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, reach_tracker
from tests.service.conftest import Server, wait_for
from tests.streams.live import start_stream, status

pytestmark = pytest.mark.slow


def test_streams_from_settings_start_with_the_service_and_survive_a_restart(tmp_path, shared_data):
    configured = json.dumps([{"camera": "gate", "idle_after": 1.0}])
    server = Server(tmp_path / "data", workers=1, streams=configured).start()
    try:
        with server.client() as client:
            wait_for(lambda: status(client, "gate")["state"] == "waiting", 60, "gate to start")
            created = client.post("/v1/streams", json={"camera": "hall"})
            assert created.status_code == 201
        server.stop()
        server.start()
        with server.client() as client:
            states = wait_for(
                lambda: (
                    {s["id"]: s["state"] for s in client.get("/v1/streams").json()["streams"]}
                    if all(
                        s["state"] == "waiting" for s in client.get("/v1/streams").json()["streams"]
                    )
                    else None
                ),
                60,
                "both streams to start again",
            )
            assert states == {"gate": "waiting", "hall": "waiting"}
            # A second instance on its own Zenoh port, connected to this one, sees that the
            # camera is taken (liveliness) and refuses it.
            other = Server(
                tmp_path / "other",
                workers=1,
                zenoh_connect=json.dumps(list(server.zenoh_listen)),
            ).start()
            try:
                with other.client() as other_client:

                    def refused():
                        response = other_client.post("/v1/streams", json={"camera": "gate"})
                        return response if response.status_code == 409 else None

                    response = wait_for(refused, 30, "the other instance to see the token")
                    assert "another instance" in response.json()["detail"]
            finally:
                other.stop()
    finally:
        server.stop()


def test_a_stream_whose_worker_keeps_failing_says_why_and_can_be_started_again(
    shared_data, tmp_path
):
    # The DPM model moved away under a running service: each new worker fails to load it.
    # Before: "the worker process died (exit code 1); gave up after 5 quick restarts", and a
    # POST to start the camera again was refused: "camera ... is tracked already".
    model = tmp_path / "person.mat"
    shutil.copyfile(shared_data / "dpm" / "INRIA" / "inriaperson_final.mat", model)
    server = Server(tmp_path / "data", workers=1, dpm_model=model).start()
    session = member_session(ZenohOptions(listen=server.zenoh_listen))
    camera, spec = "lantern", {"detector": {"name": "dpm"}}
    try:
        with server.client() as client:
            start_stream(client, session, camera, **spec)
            model.rename(tmp_path / "moved.mat")
            os.kill(status(client, camera)["worker_pid"], signal.SIGKILL)
            failed = wait_for(
                lambda: (s := status(client, camera))["state"] == "failed" and s, 120, "failed"
            )
            assert failed["error"].startswith("the worker process failed ("), failed
            assert str(model) in failed["error"]
            assert failed["error"].endswith("; gave up after 5 quick restarts")
            (tmp_path / "moved.mat").rename(model)
            again = client.post("/v1/streams", json={"camera": camera, **spec})
            assert again.status_code == 201, again.text
            wait_for(lambda: status(client, camera)["state"] == "waiting", 60, "a new worker")
            assert reach_tracker(session, StreamKeys("vtrack", camera), timeout=30)
            assert status(client, camera)["error"] is None
    finally:
        session.close()
        server.stop()
