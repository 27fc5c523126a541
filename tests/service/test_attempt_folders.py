"""Partial results go when their attempt is over (service/jobs/files.py): a new
attempt, a failure, a time limit, a cancellation, a restart. Real servers, real files."""

from __future__ import annotations

import os
import shutil
import signal

import pytest

from service.jobs.store import JobStore
from tests.service.conftest import (
    FAST_OPTIONS,
    submit,
    wait_for,
    wait_for_frames,
    wait_for_state,
)

pytestmark = pytest.mark.slow

# every format, so that every kind of partial file is there: MCAP, MP4, MOT, the JSON's points
ALL_FORMATS = {**FAST_OPTIONS, "formats": ["json", "mcap", "mot", "mp4"]}


def _listing(server, job_id) -> list[str] | None:
    """What the job's result folder holds; ``None`` when there is no folder."""
    folder = server.data_dir / "results" / job_id
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else None


def _worker_pid(server, job_id) -> int:
    store = JobStore(server.data_dir / "jobs.sqlite3")
    try:
        return store.get(job_id).worker_pid
    finally:
        store.close()


def test_a_new_attempt_removes_the_earlier_ones_and_a_cancelled_job_leaves_nothing(
    make_server, long_video
):
    # Before: .attempt-1 (partial MCAP, MP4, MOT, JSON points) stayed beside .attempt-2, and
    # after the cancellation the job's folder stayed with both.
    first = make_server(workers=1)
    with first.client() as client:
        job_id = submit(client, long_video, ALL_FORMATS).json()["id"]
        wait_for_frames(client, job_id, 3)
    assert _listing(first, job_id) == [".attempt-1"]
    first.kill()  # the job is requeued by the next service

    second = make_server(data_dir=first.data_dir, workers=1)
    with second.client() as client:
        assert wait_for_frames(client, job_id, 2)["attempts"] == 2
        assert _listing(second, job_id) == [".attempt-2"]
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 202
        status = wait_for_state(client, job_id, ("cancelled",), timeout=30)
        assert status["error"] == "cancelled on request"  # the record and its error stay
    assert _listing(second, job_id) is None


def test_a_job_over_the_time_limit_leaves_no_partial_results(make_server, long_video):
    server = make_server(workers=1, job_timeout=1.5)
    with server.client() as client:
        job_id = submit(client, long_video, ALL_FORMATS).json()["id"]
        status = wait_for_state(client, job_id, ("succeeded", "failed"), timeout=30)
        assert "exceeded the time limit" in status["error"]
    # removed once the killed worker is dead, by the supervisor's next look (a quarter second)
    wait_for(lambda: _listing(server, job_id) is None, 10, "the partial results to go")


def test_a_job_whose_worker_died_leaves_no_partial_results(make_server, long_video):
    server = make_server(workers=1)
    with server.client() as client:
        job_id = submit(client, long_video, ALL_FORMATS).json()["id"]
        wait_for_frames(client, job_id, 3)
        os.kill(_worker_pid(server, job_id), signal.SIGKILL)
        status = wait_for_state(client, job_id, ("succeeded", "failed"), timeout=30)
        assert "worker process running this job died" in status["error"]
    wait_for(lambda: _listing(server, job_id) is None, 10, "the partial results to go")


def test_a_job_failed_at_a_restart_leaves_no_partial_results(make_server, long_video):
    # The service died while the job ran its last allowed attempt: the next one fails it when
    # it starts, and removes what the attempt wrote before it answers.
    first = make_server(workers=1, max_attempts=1)
    with first.client() as client:
        job_id = submit(client, long_video, ALL_FORMATS).json()["id"]
        wait_for_frames(client, job_id, 3)
    first.kill()
    second = make_server(data_dir=first.data_dir, workers=1, max_attempts=1)
    assert _listing(second, job_id) is None
    with second.client() as client:
        status = client.get(f"/v1/jobs/{job_id}").json()
        assert status["state"] == "failed"
        assert "the service died while this job ran" in status["error"]


def test_results_removed_under_a_running_job_fail_it_saying_so(make_server, long_video, pets_cut):
    # An operator's `rm -rf data/results` mid-job: before, "internal error while tracking
    # (FileNotFoundError: ...)" with a traceback in the log.
    server = make_server(workers=1)
    with server.client() as client:
        job_id = submit(client, long_video, ALL_FORMATS).json()["id"]
        wait_for_frames(client, job_id, 2)
        shutil.rmtree(server.data_dir / "results")
        status = wait_for_state(client, job_id, ("succeeded", "failed"))
        assert status["state"] == "failed", status
        assert status["error"] == (
            f"the job's results folder {server.data_dir / 'results' / job_id} was removed while "
            "the job ran (by hand, or by a program cleaning the data folder); submit the job again"
        )
        # the service goes on: the next job succeeds
        again = submit(client, pets_cut, {"formats": ["json"]}).json()["id"]
        assert wait_for_state(client, again, ("succeeded", "failed"))["state"] == "succeeded"
    assert "Traceback" not in server.log()
