"""The job store on its own: claims, fencing of stale workers, requeue after a stop."""

from __future__ import annotations

import sqlite3

import pytest

from api_schemas.jobs import JobState
from service.jobs.store import JobStore


@pytest.fixture
def store(tmp_path):
    store = JobStore(tmp_path / "jobs.sqlite3")
    yield store
    store.close()


def _job(store, job_id="a"):
    return store.create(job_id, {"formats": ["json"]}, store.path.parent / "v", store.path.parent)


def test_jobs_are_claimed_oldest_first_once(store):
    for job_id in ("first", "second"):
        _job(store, job_id)
    assert store.claim(11).id == "first"
    assert store.claim(12).id == "second"
    assert store.claim(13) is None
    assert store.counts_by_state()[JobState.running] == 2


def test_a_stale_attempt_cannot_write(store, tmp_path):
    _job(store)
    stale = store.claim(11)
    # The service died; the next one requeues the job and another worker takes it.
    assert store.requeue_orphans(max_attempts=3) == (["a"], [])
    current = store.claim(22)
    assert current.attempts == 2
    assert not store.report_progress(stale, 11, 5, 1.0, 5)
    assert not store.finish(stale, 11, JobState.succeeded)
    assert store.report_progress(current, 22, 5, 1.0, 5)
    assert store.finish(current, 22, JobState.succeeded, results={"json": "t.json"})
    record = store.get("a")
    assert record.state == JobState.succeeded and record.results == {"json": "t.json"}
    assert store.counters()["frames_processed"] == 5


def test_a_job_interrupted_too_often_fails(store):
    _job(store)
    store.claim(1)
    assert store.requeue_orphans(max_attempts=2) == (["a"], [])
    assert store.get("a").state == JobState.queued
    store.claim(1)
    assert store.requeue_orphans(max_attempts=2) == ([], ["a"])
    record = store.get("a")
    assert record.state == JobState.failed and "died while this job ran, twice;" in record.error
    assert store.counters()["jobs_failed"] == 1  # /metrics counts it with the others


def test_clean_stops_do_not_use_up_a_jobs_attempts(store):
    """Restarts of the service (SIGTERM) while a long job runs, then one death: the job is
    queued again (three routine restarts used to fail it at the next start)."""
    _job(store)
    for worker in range(1, 4):
        store.claim(worker)
        assert store.requeue_running("a", worker)  # a clean stop
    store.claim(9)  # the fourth start; then the service dies
    assert store.requeue_orphans(max_attempts=2) == (["a"], [])
    store.claim(10)
    assert store.requeue_orphans(max_attempts=2) == ([], ["a"])
    record = store.get("a")
    assert record.attempts == 5 and "died while this job ran, twice;" in record.error


def test_a_job_whose_fork_server_dies_too_often_fails(store):
    """Each death of the fork server under a job counts like a death of the service: the job
    runs again, then fails once it has happened max_attempts times (a job whose memory makes
    the OOM killer take the fork server must not do so forever); clean stops do not count."""
    _job(store)
    store.claim(1)
    assert store.requeue_running("a", 1)  # a clean stop
    store.claim(2)
    assert store.requeue_dead("a", 3, max_attempts=2) is None  # not the job's worker
    assert store.requeue_dead("a", 2, max_attempts=2) is JobState.queued
    store.claim(4)
    assert store.requeue_dead("a", 4, max_attempts=2) is JobState.failed
    record = store.get("a")
    assert record.state == JobState.failed and "fork server died while this job ran, twice;" in (
        record.error
    )
    assert store.counters()["jobs_failed"] == 1


def test_a_database_of_an_earlier_release_gets_the_new_columns(tmp_path):
    """A data folder from before the ``stops`` and ``progressed_at`` columns keeps its jobs
    and works."""
    path = tmp_path / "jobs.sqlite3"
    JobStore(path).close()
    with sqlite3.connect(path) as db:
        db.execute("ALTER TABLE jobs DROP COLUMN stops")
        db.execute("ALTER TABLE jobs DROP COLUMN progressed_at")
        db.execute(
            "INSERT INTO jobs (id, state, options, video_path, result_dir, created_at, attempts)"
            " VALUES ('old', 'running', '{}', 'v', 'r', 1.0, 1)"
        )
    store = JobStore(path)
    try:
        assert store.requeue_orphans(max_attempts=3) == (["old"], [])
        assert store.requeue_running("old", 5) is False  # not running: nothing to do
        job = store.claim(5)
        assert job.progressed_at == job.started_at
        assert store.requeue_running("old", 5)
    finally:
        store.close()


def test_progress_moves_only_with_frames_read(store):
    _job(store, "a")
    job = store.claim(7)
    assert store.waits() == (None, job.started_at)
    assert store.report_progress(job, 7, 5, 10.0, 5)
    moved = store.get("a").progressed_at
    assert moved > job.started_at
    assert store.report_progress(job, 7, 5, 9.0, 0)  # the same frame: no progress
    assert store.get("a").progressed_at == moved
    assert store.report_progress(job, 7, 6, 9.0, 1)
    assert store.get("a").progressed_at > moved
    _job(store, "b")
    assert store.waits()[0] == store.get("b").created_at


def test_cancel_queued_at_once_running_through_the_worker(store):
    _job(store, "queued")
    assert store.request_cancel("queued") == JobState.cancelled
    _job(store, "running")
    job = store.claim(7)
    assert store.request_cancel("running") == JobState.running
    assert store.cancel_requested("running")
    assert not store.report_progress(job, 7, 1, None, 1)
    assert store.request_cancel("missing") is None
    assert store.finish(job, 7, JobState.cancelled)
    # both count as finished cancellations; the queued one never ran, so no duration
    counters = store.counters()
    assert counters["jobs_cancelled"] == 2 and counters["processing_count"] == 1


def test_a_failed_job_records_its_duration_in_the_histogram(store):
    _job(store)
    store.claim(3)
    assert store.fail_running("a", "boom", worker_pid=4) is False  # not that worker's
    assert store.fail_running("a", "boom", worker_pid=3)
    counters = store.counters()
    assert counters["jobs_failed"] == 1 and counters["processing_count"] == 1
    assert counters["processing_le_1"] == 1


def test_a_job_accepted_before_a_new_refusal_still_shows_as_it_was(store):
    # JPEG images for an mcap that is not written: accepted (and ignored) by earlier versions,
    # refused for new jobs now; the stored job must still list rather than fail every listing.
    from api_schemas.jobs import JobOptions
    from service.jobs.views import job_status

    stored = {"formats": ["json"], "mcap_images": "jpeg"}
    with pytest.raises(ValueError, match="only with the mcap format"):
        JobOptions.model_validate(stored)
    store.create("old", stored, store.path.parent / "v", store.path.parent)
    status = job_status(store.get("old"))
    assert status.options.mcap_images == "jpeg" and status.state == JobState.queued


def _bytes_on_disk(path):
    """Every byte of a database and its write-ahead log."""
    return b"".join(p.read_bytes() for p in path.parent.glob(path.name + "*"))


def test_a_deleted_job_leaves_no_copy_of_its_file_name_on_disk(store):
    # a client's file name is personal data (a shop, a camera, a name)
    for job_id in ("a", "b"):
        store.create(
            job_id, {}, store.path / "v", store.path, video_filename=f"JaneDoe-{job_id}.avi"
        )
    store.finish(store.claim(11), 11, JobState.succeeded)
    assert b"JaneDoe-a" in _bytes_on_disk(store.path)
    assert store.delete("a")
    # before: the write-ahead log kept the row's pages until the service's next start
    on_disk = _bytes_on_disk(store.path)
    assert b"JaneDoe-a" not in on_disk
    assert b"JaneDoe-b" in on_disk  # the other job is intact
    assert store.get("b").video_filename == "JaneDoe-b.avi"


def test_job_files_are_found_in_a_data_folder_moved_since_they_were_stored(tmp_path):
    old, new = tmp_path / "old", tmp_path / "new"
    store = JobStore(old / "jobs.sqlite3")
    store.create("a", {}, old / "uploads" / "a.mp4", old / "results" / "a")
    store.create("b", {}, old / "uploads" / "b.mp4", old / "results" / "b")
    # "b" as earlier versions stored it: the whole path, as the service then saw it
    with sqlite3.connect(store.path) as db:
        db.execute(
            "UPDATE jobs SET video_path = ?, result_dir = ? WHERE id = 'b'",
            (str(old / "uploads" / "b.mp4"), str(old / "results" / "b")),
        )
        stored = db.execute("SELECT video_path, result_dir FROM jobs WHERE id = 'a'").fetchone()
    store.close()
    assert stored == ("uploads/a.mp4", "results/a")
    old.rename(new)
    store = JobStore(new / "jobs.sqlite3")
    try:
        for job_id in ("a", "b"):
            record = store.get(job_id)
            assert record.video_path == new / "uploads" / f"{job_id}.mp4"
            assert record.result_dir == new / "results" / job_id
    finally:
        store.close()
