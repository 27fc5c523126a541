"""Two service instances on one PostgreSQL job database and one data folder (issue 79): real
``vtrack serve`` processes, a real server. Uploads to either run on both, any instance serves
any job, and the jobs of an instance killed with ``kill -9`` finish on the other, once."""

from __future__ import annotations

import signal
import uuid

import psycopg
import pytest

from devtools.testing import Server, wait_for
from tests.service.conftest import (
    FAST_OPTIONS,
    error_of,
    submit,
    wait_for_frames,
    wait_for_state,
)

pytestmark = pytest.mark.scaleout

LEASE = 3.0
"""Seconds a claim holds unless renewed: short, so that a dead instance's job moves soon."""


@pytest.fixture
def instances(postgres, tmp_path):
    """Instances ``a`` and ``b`` of one database and data folder, one worker each."""
    name = f"jobs_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres.url, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    url = postgres.url.rsplit("/", 1)[0] + f"/{name}"
    started: dict[str, Server] = {}
    for instance in ("a", "b"):
        started[instance] = Server(
            tmp_path / "data",
            workers=1,
            name=instance,
            database_url=url,
            instance_name=instance,
            job_lease_seconds=LEASE,
            zenoh_enabled="false",
        ).start()
    yield started, url
    for server in started.values():
        server.stop()


def ran_on(url: str) -> dict[str, str]:
    with psycopg.connect(url) as connection:
        return dict(connection.execute("SELECT id, instance FROM jobs").fetchall())


def test_uploads_to_either_instance_run_on_both_and_either_serves_them(instances, pets_short):
    servers, url = instances
    with servers["a"].client() as a, servers["b"].client() as b:
        ids = [submit(client, pets_short, FAST_OPTIONS).json()["id"] for client in (a, b) * 3]
        for job_id in ids:
            wait_for_state(b, job_id, ("succeeded",), timeout=180)
        assert set(ran_on(url).values()) == {"a", "b"}
        listed = {job["id"] for job in a.get("/v1/jobs").json()["jobs"]}
        assert listed == set(ids)
        for job_id, instance in ran_on(url).items():
            other = b if instance == "a" else a  # the results are fetched from the other
            response = other.get(f"/v1/jobs/{job_id}/result")
            assert response.status_code == 200, response.text
            document = response.json()
            assert document["job_id"] == job_id and document["frames_processed"] == 8


def test_a_killed_instance_s_job_finishes_on_the_other_once(instances, long_video):
    servers, url = instances
    with servers["a"].client() as a, servers["b"].client() as b:
        # b busy with a job of its own, so that a takes the next (each has one worker)
        first = submit(b, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(b, first, 1)
        job_id = submit(a, long_video, FAST_OPTIONS).json()["id"]
        wait_for(lambda: ran_on(url).get(job_id) in ("a", "b"), 60, "the job to be claimed")
        victim, survivor = (a, b) if ran_on(url)[job_id] == "a" else (b, a)
        name = "a" if victim is a else "b"
        wait_for_frames(victim, job_id, 10)
        servers[name].process.send_signal(signal.SIGKILL)
        servers[name].process.wait(10)
        status = wait_for_state(survivor, job_id, ("succeeded", "failed"), timeout=180)
        assert status["state"] == "succeeded", status
        assert ran_on(url)[job_id] != name
        with psycopg.connect(url) as connection:
            (attempts,) = connection.execute(
                "SELECT attempts FROM jobs WHERE id = %s", (job_id,)
            ).fetchone()
        assert attempts == 2  # the killed start and the one that finished: not run twice more
        assert wait_for_state(survivor, first, ("succeeded",))["state"] == "succeeded"
        log = servers["b" if name == "a" else "a"].log()
        assert f"job {job_id} queued again: the instance running it was lost" in log


def test_jobs_go_on_when_the_database_restarts(postgres, instances, long_video):
    servers, _ = instances
    with servers["a"].client() as a:
        job_id = submit(a, long_video, FAST_OPTIONS).json()["id"]
        wait_for_frames(a, job_id, 10)
        postgres.kill()
        unavailable = a.get(f"/v1/jobs/{job_id}")
        assert unavailable.headers["retry-after"] == "5"
        # the family's whole sentence, once
        assert error_of(unavailable, "unavailable")["detail"] == (
            "the job database (VTRACK_DATABASE_URL) cannot be reached just now; try again in a "
            "few seconds"
        )
        postgres.restart()
        status = wait_for_state(a, job_id, ("succeeded", "failed"), timeout=180)
        assert status["state"] == "succeeded", status
        later = submit(a, long_video, FAST_OPTIONS).json()["id"]  # a new upload runs too
        assert wait_for_state(a, later, ("succeeded", "failed"))["state"] == "succeeded"
