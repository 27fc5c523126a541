"""Twenty random ``kill -9`` of two instances that share one PostgreSQL job database (issue 79):
real ``vtrack serve`` processes, each killed in turn while its worker runs a job and started
again at once, as systemd's ``Restart=`` or compose's ``restart:`` does. No accepted job is lost
or run twice: every job succeeds once, with one complete result."""

from __future__ import annotations

import random
import re
import uuid

import psycopg
import pytest

from devtools.testing import Server, wait_for
from tests.service.conftest import FAST_OPTIONS, submit, wait_for_state

pytestmark = pytest.mark.scaleout

KILLS = 20
LEASE = 2.0


def running_on(url: str, instance: str) -> str | None:
    """The job ``instance``'s worker runs, if it has read a frame (None: none)."""
    with psycopg.connect(url) as connection:
        row = connection.execute(
            "SELECT id FROM jobs WHERE state = 'running' AND instance = %s AND frames_done > 0",
            (instance,),
        ).fetchone()
    return row[0] if row else None


@pytest.mark.timeout(900)
def test_twenty_random_kills_lose_no_job_and_run_none_twice(postgres, tmp_path, pets_cut):
    name = f"jobs_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres.url, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    url = postgres.url.rsplit("/", 1)[0] + f"/{name}"
    servers = {
        instance: Server(
            tmp_path / "data",
            workers=1,
            name=instance,
            database_url=url,
            instance_name=instance,
            job_lease_seconds=LEASE,
            max_attempts=100,  # the kills are counted, not allowed to fail a job
            zenoh_enabled="false",
        )
        for instance in ("a", "b")
    }
    chance = random.Random(79)
    accepted: list[str] = []
    kills = 0
    try:
        for server in servers.values():
            server.start()

        def keep_queue_filled() -> None:
            with servers[chance.choice("ab")].client() as client:
                states = [client.get(f"/v1/jobs/{j}").json()["state"] for j in accepted[-4:]]
                if states.count("queued") < 2:
                    response = submit(client, pets_cut, FAST_OPTIONS)
                    assert response.status_code == 202, response.text
                    accepted.append(response.json()["id"])

        while kills < KILLS:
            keep_queue_filled()
            victim = chance.choice("ab")
            job = wait_for(
                lambda v=victim: keep_queue_filled() or running_on(url, v), 60, "a running job"
            )
            servers[victim].kill()
            kills += 1
            servers[victim].start()
            assert job in accepted
        with servers["a"].client() as client:
            for job_id in accepted:
                status = wait_for_state(client, job_id, ("succeeded", "failed"), timeout=300)
                assert status["state"] == "succeeded", status
                document = client.get(f"/v1/jobs/{job_id}/result").json()
                assert document["frames_processed"] == 24
            listed = {job["id"] for job in client.get("/v1/jobs?limit=1000").json()["jobs"]}
        assert listed == set(accepted)  # none lost, none made up
        log = servers["a"].log() + servers["b"].log()
        succeeded = re.findall(r"job (\S+): succeeded", log)
        assert sorted(succeeded) == sorted(accepted)  # each finished once, by one worker
        assert log.count("queued again") >= KILLS // 2  # by the survivor, or at the restart
        assert not list((tmp_path / "data" / "results").glob("*/.attempt-*"))
    finally:
        for server in servers.values():
            server.stop()
