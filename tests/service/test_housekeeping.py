"""A long-running service does not fill its disk: finished jobs' uploads go, and with a retention
the jobs themselves (a real server, real files)."""

from __future__ import annotations

import os
import re
import time

import pytest

from tests.service.conftest import FAST_OPTIONS, submit, wait_for, wait_for_state

pytestmark = pytest.mark.slow


def _files(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


def test_a_finished_jobs_upload_is_removed_and_its_results_stay(make_server, pets_short):
    server = make_server(workers=1, housekeeping_interval=0.3)
    uploads = server.data_dir / "uploads"
    with server.client() as client:
        job_id = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        assert wait_for_state(client, job_id, ("succeeded", "failed"))["state"] == "succeeded"
        wait_for(lambda: not _files(uploads), 10, "the finished job's upload to be removed")
        assert client.get(f"/v1/jobs/{job_id}/result").json()["frames_processed"] == 8
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 204  # no upload to remove
    log = server.log()
    assert "housekeeping: the uploads of 1 finished jobs removed" in log
    assert f"job {job_id} (succeeded) deleted with its files" in log


def test_jobs_past_the_retention_are_deleted_with_their_results(make_server, pets_short):
    # 0.0005 h = 1.8 s after they finished
    server = make_server(workers=1, housekeeping_interval=0.3, retention_hours=0.0005)
    with server.client() as client:
        job_id = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        assert wait_for_state(client, job_id, ("succeeded", "failed"))["state"] == "succeeded"
        assert client.get(f"/v1/jobs/{job_id}/result").status_code == 200  # kept a while
        wait_for(
            lambda: client.get(f"/v1/jobs/{job_id}").status_code == 404, 20, "the job to expire"
        )
    assert not _files(server.data_dir / "results") and not _files(server.data_dir / "uploads")
    # by id (before: "0 uploads and 1 expired jobs removed", though its upload went too)
    assert re.search(
        rf"housekeeping: job {job_id} \(succeeded \d+\.\d h ago\) deleted with its files "
        r"\(VTRACK_RETENTION_HOURS=0.0005\)",
        server.log(),
    )


def test_at_start_uploads_no_job_owns_are_removed_and_unknown_results_kept(make_server, pets_short):
    first = make_server(workers=1)
    with first.client() as client:
        job_id = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        wait_for_state(client, job_id, ("succeeded", "failed"))
    first.stop()
    uploads = first.data_dir / "uploads"
    (uploads / "0123abcd.receiving").write_bytes(b"half an upload, cut by a crash")
    results = first.data_dir / "results"
    # Results of a job the database does not know: it was restored from an older copy. Before,
    # they were deleted as a deletion cut short (which now removes the files first).
    (results / "0123abcd").mkdir()
    (results / "0123abcd" / "trajectories.json").write_text("{}")
    second = make_server(data_dir=first.data_dir, workers=1)
    assert not _files(uploads) and _files(results) == sorted(["0123abcd", job_id])
    log = second.log()
    assert "housekeeping: 1 uploads that no job owns removed" in log
    assert (
        "WARNING service.jobs.housekeeping: housekeeping: 1 result folders belong to no job" in log
    )
    assert f"left in {results}: 0123abcd" in log
    with second.client() as client:
        assert client.get(f"/v1/jobs/{job_id}/result").json()["frames_processed"] == 8


def test_stream_recordings_past_the_retention_are_deleted(make_server, tmp_path):
    # before: VTRACK_RETENTION_HOURS covered jobs only; a camera's footage stayed for ever
    folder = tmp_path / "data" / "streams" / "gate"
    folder.mkdir(parents=True)
    hour_ago, in_an_hour = time.time() - 3600, time.time() + 3600
    for name, when in [
        ("gate-1.mcap", hour_ago),  # finished an hour ago
        ("gate-2.mcap.broken", hour_ago),  # a killed worker's, which could not be salvaged
        ("gate-3.mcap", in_an_hour),  # finished now (as the clock of the test sees it)
        ("gate-4.mcap.partial", hour_ago),  # still being written
    ]:
        (folder / name).write_bytes(b"footage")
        os.utime(folder / name, (when, when))
    server = make_server(tmp_path / "data", housekeeping_interval=0.3, retention_hours=1.5 / 3600)
    wait_for(lambda: not (folder / "gate-1.mcap").exists(), 20, "the old recording to expire")
    assert _files(folder) == ["gate-3.mcap", "gate-4.mcap.partial"]
    log = server.log()
    assert (
        "housekeeping: recording gate-1.mcap of camera gate deleted "
        "(VTRACK_RETENTION_HOURS=0.000416667)" in log
    )
    assert "recording gate-2.mcap.broken of camera gate deleted" in log
