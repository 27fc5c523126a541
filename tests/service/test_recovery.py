"""Jobs survive the service: a restart mid-job, and a worker killed mid-job."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import time

import pytest

from service.jobs.store import JobStore
from tests.conftest import process_alive
from tests.service.conftest import (
    FAST_OPTIONS,
    Server,
    metrics,
    submit,
    wait_for,
    wait_for_frames,
    wait_for_state,
)

pytestmark = pytest.mark.slow


def _worker_pid(data_dir, job_id) -> int:
    store = JobStore(data_dir / "jobs.sqlite3")
    try:
        return store.get(job_id).worker_pid
    finally:
        store.close()


def test_a_job_running_when_the_service_dies_completes_after_a_restart(make_server, long_video):
    first = make_server(workers=1)
    with first.client() as client:
        job_id = submit(client, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, job_id, 3)
    worker = _worker_pid(first.data_dir, job_id)
    first.kill()
    # The orphaned worker notices that its service is gone and stops by itself.
    wait_for(lambda: not process_alive(worker), 20, f"the orphaned worker {worker} to stop")

    second = make_server(data_dir=first.data_dir, workers=1)
    with second.client() as client:
        status = wait_for_state(client, job_id, ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        assert status["attempts"] == 2
        document = client.get(f"/v1/jobs/{job_id}/result").json()
        assert document["frames_processed"] == 150
    assert not list((first.data_dir / "results" / job_id).glob(".attempt-*"))


def test_a_stop_signal_to_the_whole_group_requeues_the_running_job(make_server, long_video):
    # systemctl stop (KillMode=control-group) and Ctrl-C signal every process of the service:
    # the workers leave the stop to the service, which requeues their jobs
    first = make_server(workers=1)
    with first.client() as client:
        job_id = submit(client, long_video, FAST_OPTIONS).json()["id"]
        before = wait_for_frames(client, job_id, 3)["progress"]["frames_done"]
        worker = _worker_pid(first.data_dir, job_id)
        os.kill(worker, signal.SIGTERM)
        os.kill(worker, signal.SIGINT)
        wait_for_frames(client, job_id, before + 2)  # the same worker tracks on
        assert process_alive(worker) and _worker_pid(first.data_dir, job_id) == worker
    first.stop()
    assert "queued again: the service stopped while it ran" in first.log()
    assert "died" not in first.log()

    second = make_server(data_dir=first.data_dir, workers=1)
    with second.client() as client:
        status = wait_for_state(client, job_id, ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        assert status["attempts"] == 2


def test_a_stalled_job_is_failed_and_its_worker_replaced(make_server, long_video, pets_short):
    # A worker that stops reading frames (a decoder that hangs; here SIGSTOP) held its job and
    # its place for the whole time limit (4 h), with nothing in the metrics to alert on.
    server = make_server(workers=1, job_stall_timeout=3)
    with server.client() as client:
        stalled = submit(client, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, stalled, 3)
        waiting = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        worker = _worker_pid(server.data_dir, stalled)
        os.kill(worker, signal.SIGSTOP)

        def a_second_stalled() -> dict[str, float] | None:
            figures = metrics(client)
            stalled = figures["vtrack_running_job_stall_seconds"] >= 1.0
            return (
                figures if stalled and figures["vtrack_oldest_queued_job_seconds"] >= 1.0 else None
            )

        figures = wait_for(a_second_stalled, 10, "a second of stall in the metrics")
        assert figures["vtrack_running_job_stall_seconds"] < 3.5
        status = wait_for_state(client, stalled, ("succeeded", "failed"), timeout=30)
        assert status["state"] == "failed"
        assert "read no frame for 3 s (VTRACK_JOB_STALL_TIMEOUT)" in status["error"]
        wait_for(lambda: not process_alive(worker), 10, "the stopped worker to be killed")
        status = wait_for_state(client, waiting, ("succeeded", "failed"))
        assert status["state"] == "succeeded", status  # on the worker that replaced it
        figures = metrics(client)
        assert figures["vtrack_running_job_stall_seconds"] == 0
        assert figures["vtrack_oldest_queued_job_seconds"] == 0
        assert figures["vtrack_workers_replaced_total"] == 1


def test_a_killed_worker_fails_its_job_and_the_next_job_succeeds(
    make_server, long_video, pets_short
):
    server = make_server(workers=1)
    with server.client() as client:
        doomed = submit(client, long_video, FAST_OPTIONS).json()["id"]
        following = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, doomed, 3)
        os.kill(_worker_pid(server.data_dir, doomed), signal.SIGKILL)
        status = wait_for_state(client, doomed, ("succeeded", "failed"))
        assert status["state"] == "failed"
        assert "worker process running this job died (killed by SIGKILL)" in status["error"]
        assert client.get(f"/v1/jobs/{doomed}/result").status_code == 409
        status = wait_for_state(client, following, ("succeeded", "failed"))
        assert status["state"] == "succeeded", status
        ready = client.get("/readyz").json()["workers_ready"]
        assert ready == 1 and type(ready) is int  # a count (was true, and 0 while starting)


def _children(pid: int) -> set[int]:
    children = set()
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as listed:
            children.update(int(child) for child in listed.read().split())
    return children


def _worker_pids(server) -> set[int]:
    """The service's job worker processes: the children of its fork server."""
    workers = set()
    for child in _children(server.process.pid):
        try:
            with open(f"/proc/{child}/cmdline", "rb") as cmdline:
                if b"forkserver" in cmdline.read():
                    workers |= _children(child)
        except FileNotFoundError:
            continue
    return workers


def test_the_service_stops_after_an_idle_worker_was_killed(make_server):
    # A worker killed while it waits for work (the OOM killer, a kill -9, or a service manager
    # sending SIGTERM to the whole process group) must not keep the service from stopping.
    server = make_server(workers=1)
    (first,) = _worker_pids(server)
    os.kill(first, signal.SIGKILL)
    with server.client() as client:
        wait_for(
            lambda: (
                _worker_pids(server) - {first}
                and client.get("/readyz").json()["workers_ready"] == 1
            ),
            30,
            "the killed worker to be replaced",
        )
    server.process.send_signal(signal.SIGTERM)
    server.process.wait(timeout=30)  # it hung for ever in the stop signal to the workers
    assert "worker processes stopped" in server.log()
    assert "Application shutdown complete" in server.log()


def test_a_stop_signal_while_the_workers_start_replaces_none_of_them(tmp_path):
    # systemctl stop or Ctrl-C just after a start. Spawned, the job and stream workers were
    # still importing, did not ignore SIGTERM yet and died of the group's signal; while the
    # service waited for an upload in progress, its supervisor took them for crashes and
    # started new ones. Forked from the fork server, they ignore it from their first moment.
    server = Server(tmp_path / "data", workers=2, own_group=True,
                    streams=json.dumps([{"camera": "gate"}]))  # fmt: skip
    server.start(ready=False)  # answering: the workers were started a moment ago
    try:
        with socket.create_connection(("127.0.0.1", server.port), timeout=20) as upload:
            upload.sendall(
                b"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                b"Content-Type: multipart/form-data; boundary=b\r\nContent-Length: 100000\r\n\r\n"
                b'--b\r\nContent-Disposition: form-data; name="video"; filename="a.avi"\r\n\r\n'
            )
            uploads = server.data_dir / "uploads"
            wait_for(lambda: any(uploads.glob("*.receiving")), 20, "the service to read the upload")
            server.signal_group(signal.SIGTERM)
            # the stop waits for the upload: held open longer than a worker's death is held back
            # (a pause that is the test: the service must keep its workers all that time)
            time.sleep(5)
        assert server.process.wait(timeout=30) == -signal.SIGTERM
    finally:
        server.stop()
    log = server.log()
    assert "stream gate: worker" in log and "worker processes stopped" in log
    assert "killed by SIGTERM" not in log and "had ended" not in log
    assert "replaced" not in log and "died" not in log and "restart" not in log
    assert "Application shutdown complete" in log


def test_every_log_line_of_the_service_carries_its_time(make_server, pets_short):
    # Operators place crashes, timeouts and cancellations in time from the log alone; the API
    # process's and uvicorn's lines had none (only the workers' had).
    server = make_server(workers=1)
    with server.client() as client:
        job = submit(client, pets_short, {"formats": ["json"]}).json()["id"]
        wait_for_state(client, job, ("succeeded",), timeout=60)
        assert client.get("/v1/jobs/no-such-job").status_code == 404
    server.stop()
    stamped = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} [A-Z]+ ")
    lines = [line for line in server.log().splitlines() if not line.startswith("vtrack: ")]
    assert any("GET /v1/jobs/no-such-job" in line for line in lines)  # the access log
    assert any("uvicorn.error: Application startup complete" in line for line in lines)
    unstamped = [line for line in lines if not stamped.match(line)]
    assert not unstamped, unstamped


def test_a_stop_does_not_wait_for_clients_watching_events(make_server, long_video):
    # docker stop sends SIGTERM and kills 10 s later: a client following a job's events held
    # the stop for uvicorn's whole graceful-shutdown timeout (10 s), and the kill came first
    server = make_server(workers=1)
    with server.client() as client:
        job_id = submit(client, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(client, job_id, 2)
        with client.stream("GET", f"/v1/jobs/{job_id}/events", timeout=30) as events:
            lines = events.iter_lines()
            assert next(lines).startswith("event: progress")
            started = time.monotonic()
            server.process.send_signal(signal.SIGTERM)
            rest = list(lines)  # the stream ends when the service stops
            server.process.wait(timeout=30)
            took = time.monotonic() - started
    assert took < 5, f"the stop took {took:.1f} s"
    assert not any(line.startswith("event: end") for line in rest)  # the job did not end
    assert "graceful shutdown exceeded" not in server.log()
    assert "queued again: the service stopped while it ran" in server.log()
