"""Live streams through a service's life: streams from its settings across a restart, a
worker that keeps failing, a camera configured on two instances. Lifecycle only, no rates
measured: not marked realtime, these run beside other tests."""

from __future__ import annotations

import json
import os
import shutil
import signal

import pytest

from service.streams.keys import StreamKeys
from service.streams.session import ZenohOptions
from service.streams.tools import member_session, reach_tracker
from tests.service.conftest import Server, error_of, wait_for
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
                    assert "another instance" in error_of(response, "conflict")["detail"]
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


def test_a_camera_configured_on_two_instances_has_one_tracker_and_a_standby(tmp_path):
    configured = json.dumps([{"camera": "gate"}])
    first = Server(tmp_path / "first", workers=1, streams=configured).start()
    servers = [first]
    try:
        with first.client() as client:
            wait_for(lambda: status(client, "gate")["state"] == "waiting", 60, "gate to start")
        connect = json.dumps(list(first.zenoh_listen))
        servers.append(
            Server(
                tmp_path / "second", workers=1, streams=configured, zenoh_connect=connect
            ).start()
        )

        def gate_everywhere() -> list[dict]:
            statuses = []
            for server in servers:
                with server.client() as client:
                    statuses.append(status(client, "gate"))
            return statuses

        # before: both tracked gate, their tracks interleaved on one key with clashing ids.
        # The one that had it first keeps it.
        _, standby = wait_for(
            lambda: (
                (found := gate_everywhere())
                and [s["state"] for s in found] == ["waiting", "standby"]
                and found
            ),
            60,
            "the first instance to track gate and the second to stand by",
        )
        assert standby["worker_pid"] is None
        assert standby["error"].startswith("camera gate is tracked by another instance")
        # The first's worker dies three times quickly: its restart waits 4 s, in which the
        # standby sees no token and takes over; once the first's new worker is back, the two
        # track gate, and the second, the younger, stands by again.
        with first.client() as client:
            for starts in (2, 3, 4):
                os.kill(status(client, "gate")["worker_pid"], signal.SIGKILL)
                wait_for(
                    lambda starts=starts: status(client, "gate")["worker_starts"] == starts,
                    60,
                    f"worker {starts} of the first instance",
                )
        wait_for(
            lambda: (
                [(s["state"], s["worker_starts"]) for s in gate_everywhere()]
                == [("waiting", 4), ("standby", 1)]
            ),
            60,
            "the second to have taken over and made way again",
        )
        first.stop()
        with servers[1].client() as client:
            took_over = wait_for(
                lambda: (s := status(client, "gate"))["state"] == "waiting" and s,
                60,
                "the standby to take over",
            )
        assert took_over["error"] is None and took_over["worker_pid"] is not None
    finally:
        for server in servers:
            server.stop()
