"""The job store on a real PostgreSQL server (issue 79): claims that never take one job twice,
across processes; leases that requeue the jobs of an instance that died, and only those; the
fencing of an old attempt; workers woken by ``NOTIFY``; the schema's versions; a server that
restarts under the store."""

from __future__ import annotations

import multiprocessing
import time
from pathlib import Path

import psycopg
import pytest

from api_schemas.jobs import JobState
from devtools.testing import wait_for
from service.jobs.store import JobStore

pytestmark = pytest.mark.scaleout


def open_store(url: str, folder: Path) -> JobStore:
    return JobStore(url, folder=folder)


def add_jobs(store: JobStore, count: int) -> list[str]:
    ids = [f"job-{index:03d}" for index in range(count)]
    for job_id in ids:
        folder = store.folder
        store.create(job_id, {}, folder / "uploads" / f"{job_id}.mp4", folder / "results" / job_id)
    return ids


def _claim_all(url: str, folder: str, pid: int, out) -> None:
    """A claimer in a process of its own, as a worker of another instance is."""
    store = open_store(url, Path(folder))
    taken = []
    while (job := store.claim(pid, f"instance-{pid}", 60)) is not None:
        taken.append(job.id)
    store.close()
    out.put(taken)


def test_claimers_in_several_processes_take_each_job_once(database_url, tmp_path):
    store = open_store(database_url, tmp_path)
    ids = add_jobs(store, 60)
    context = multiprocessing.get_context("spawn")
    out = context.Queue()
    claimers = [
        context.Process(target=_claim_all, args=(database_url, str(tmp_path), pid, out))
        for pid in (101, 102, 103)
    ]
    for process in claimers:
        process.start()
    taken = [out.get(timeout=120) for _ in claimers]
    for process in claimers:
        process.join(30)
    claimed = [job_id for batch in taken for job_id in batch]
    assert sorted(claimed) == ids  # each once, none left
    assert store.counts_by_state()[JobState.running] == 60
    assert {store.get(job_id).instance for job_id in ids} <= {
        "instance-101",
        "instance-102",
        "instance-103",
    }
    store.close()


def test_a_lost_instance_s_jobs_are_requeued_when_its_lease_runs_out(database_url, tmp_path):
    store = open_store(database_url, tmp_path)
    other = open_store(database_url, tmp_path)  # another instance on the same database
    add_jobs(store, 2)
    lost = store.claim(7, "lost", lease=0.3)
    alive = other.claim(7, "alive", lease=0.3)  # same pid, another machine
    assert lost is not None and alive is not None
    # the live instance renews; the lost one does not (a pause that lets the leases of 0.3 s run
    # out: the time passing is what is tested)
    time.sleep(0.5)
    assert other.renew_leases("alive", 30) == 1
    # at its start an instance on a shared database takes only expired jobs
    requeued, failed = other.requeue_orphans(max_attempts=3)
    assert (requeued, failed) == ([lost.id], [])
    assert store.get(alive.id).state == JobState.running
    # the lost attempt, should it come back, is fenced off; the new one runs
    again = other.claim(8, "alive", lease=30)
    assert again.id == lost.id and again.attempts == 2
    assert not store.finish(lost, 7, JobState.succeeded)
    assert not store.report_progress(lost, 7, 10, 5.0, 10)
    assert other.finish(again, 8, JobState.succeeded)
    assert store.get(lost.id).state == JobState.succeeded
    store.close()
    other.close()


def test_a_job_whose_instances_keep_dying_fails(database_url, tmp_path):
    store = open_store(database_url, tmp_path)
    (job_id,) = add_jobs(store, 1)
    for _ in range(2):
        assert store.claim(1, "doomed", lease=0.0) is not None
        time.sleep(0.01)  # the lease of 0 s runs out: the time passing is what is tested
        store.requeue_expired(max_attempts=2)
    record = store.get(job_id)
    assert record.state == JobState.failed
    assert record.error == (
        "the service instance running it was lost while this job ran, twice; "
        "it is not started again"
    )
    store.close()


def test_an_idle_worker_is_woken_by_a_new_job(database_url, tmp_path):
    worker = open_store(database_url, tmp_path)
    api = open_store(database_url, tmp_path)
    worker.wait_for_work(0.1)  # listening from now on
    started = time.monotonic()
    api.create("new", {}, tmp_path / "uploads" / "new.mp4", tmp_path / "results" / "new")
    worker.wait_for_work(10.0)
    assert time.monotonic() - started < 5.0  # woken, not timed out
    assert worker.claim(1) is not None
    worker.close()
    api.close()


def test_instances_starting_together_make_the_schema_once(database_url, tmp_path):
    stores = [open_store(database_url, tmp_path) for _ in range(3)]
    with psycopg.connect(database_url) as connection:
        versions = connection.execute("SELECT version FROM schema_version").fetchall()
        assert versions == [(1,), (2,)]
        connection.execute("INSERT INTO schema_version VALUES (99)")
    with pytest.raises(RuntimeError, match="newer than this service's 2: upgrade the service"):
        open_store(database_url, tmp_path)
    for store in stores:
        store.close()


def test_the_store_goes_on_after_the_server_restarts(postgres, database_url, tmp_path):
    store = open_store(database_url, tmp_path)
    (job_id,) = add_jobs(store, 1)
    postgres.kill()
    with pytest.raises(psycopg.OperationalError):
        store.get(job_id)
    postgres.restart()
    record = wait_for(lambda: _try(store.get, job_id), 30, "the store to reconnect")
    assert record.state == JobState.queued  # committed before the kill
    assert store.claim(1, "back", 30).id == job_id
    store.close()


def _try(call, *args):
    try:
        return call(*args)
    except psycopg.OperationalError:
        return None
