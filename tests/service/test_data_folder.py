"""The data folder a service owns (service/data_folder.py): ``vtrack serve`` refuses one it cannot
write or that another service uses, in one line, before it serves; real servers, real files.

Root writes through any file mode, and the tests run as root in CI: there the refused service
runs as root without that power (``setpriv`` drops ``CAP_DAC_OVERRIDE``), so a ``chmod`` binds
it as it binds the unprivileged user a service runs as.
"""

from __future__ import annotations

import functools
import os
import re
import shutil
import stat
import subprocess
import sys

import pytest

from devtools.testing import Server, free_port, wait_for
from service.data_folder import LOCK_NAME, DataFolderInUse, claim_data_folder
from service.jobs.store import JobStore
from service.settings import Settings
from service.streams.store import StreamStore
from tests.service.conftest import (
    FAST_OPTIONS,
    error_of,
    submit,
    wait_for_frames,
    wait_for_state,
)

pytestmark = pytest.mark.slow

SETTING = "vtrack: the data folder (--data-dir, VTRACK_DATA_DIR): "


@functools.cache
def _as_an_unprivileged_user() -> tuple[str, ...]:
    """A command prefix under which file modes bind the command; empty when they do already."""
    if os.geteuid() != 0:
        return ()
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("running as root, and no setpriv to run the service without root's powers")
    # out of the bounding and inheritable sets, so the interpreter setpriv starts never has it
    prefix = (setpriv, "--inh-caps=-dac_override", "--bounding-set=-dac_override")
    probe = subprocess.run([*prefix, "true"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"setpriv cannot drop CAP_DAC_OVERRIDE here: {probe.stderr.strip()}")
    return prefix


def _serve(data_dir, *, unprivileged: bool = False) -> subprocess.CompletedProcess:
    """``vtrack serve`` on ``data_dir``, expected to stop at once (a service that started would
    run until the timeout kills it)."""
    prefix = _as_an_unprivileged_user() if unprivileged else ()
    command = [*prefix, sys.executable, "-m", "service.cli", "serve", "--workers", "1"]
    command += ["--port", str(free_port()), "--data-dir", str(data_dir)]
    env = {k: v for k, v in os.environ.items() if not k.startswith("VTRACK_")}
    env["VTRACK_ZENOH_ENABLED"] = "false"
    return subprocess.run(command, capture_output=True, text=True, timeout=30, env=env)


def _refused(result: subprocess.CompletedProcess) -> str:
    """The one line of a refusal, checked to be one."""
    assert result.returncode == 2, result.stderr
    assert "serving on" not in result.stderr and "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(SETTING), result.stderr
    return lines[0]


@pytest.mark.parametrize(
    ("name", "mode", "named"),
    [
        # root's database file, mode 644, under a service user: it started, said it was ready
        # and answered every upload 500 (SQLite opens such a file read-only without a word)
        ("jobs.sqlite3", 0o444, "cannot write the job database {path}: attempt to write a"),
        # subfolders made by root: a 38-line traceback from the lifespan and exit status 3
        ("uploads", 0o555, "cannot write into the folder {path}: Permission denied"),
        ("results", 0o555, "cannot write into the folder {path}: Permission denied"),
        # before: it started, and a stream's recording failed when it began
        ("streams", 0o555, "cannot write into the folder {path}: Permission denied"),
        # the top folder itself, refused before too: from the same place now
        (".", 0o555, "cannot write into the folder {path}: Permission denied"),
    ],
)
def test_serve_refuses_a_data_folder_it_cannot_write(tmp_path, name, mode, named):
    data = tmp_path / "data"
    for folder in ("uploads", "results", "streams"):
        (data / folder).mkdir(parents=True)
    # the database of a service that ran: every table there
    JobStore(data / "jobs.sqlite3").close()
    StreamStore(data / "jobs.sqlite3").close()
    path = data / name if name != "." else data
    path.chmod(mode)
    try:
        line = _refused(_serve(data, unprivileged=True))
    finally:
        path.chmod(0o755 if path.is_dir() else 0o644)  # for pytest's clean-up
    assert named.format(path=path) in line


def test_an_unexpected_error_in_a_request_answers_json_and_is_logged_once(make_server, pets_short):
    # An upload into a data folder broken under the running service (its uploads folder
    # replaced by a file): 500 as JSON like every other error, not Starlette's plain text. The
    # service fails before it reads the upload, which the client is still sending: the answer
    # must reach it all the same (not a connection reset).
    server = make_server(workers=1)
    uploads = server.data_dir / "uploads"
    shutil.rmtree(uploads)
    uploads.write_text("not a folder")
    with server.client() as client:
        response = submit(client, pets_short, FAST_OPTIONS)
        # the family's whole sentence, once
        assert error_of(response, "internal")["detail"] == (
            "internal error (FileExistsError) while answering POST /v1/jobs: the service's log "
            "has the details; tell its operator"
        )
        assert client.get("/readyz").status_code == 200  # the service goes on
    server.stop()
    assert server.log().count("Traceback (most recent call last)") == 1
    assert server.log().count("FileExistsError") == 1


def test_a_folder_made_read_only_under_a_running_service_is_named_not_an_internal_error(
    make_server, pets_short
):
    # before: uploads answered 500 "internal error (PermissionError)", /readyz said ready, and
    # a job failed with "internal error while tracking (PermissionError: ...)"
    server = make_server(workers=1, prefix=_as_an_unprivileged_user())
    writable = f"writable by the user the service runs as (uid {os.geteuid()})"
    with server.client() as client:
        for name in ("uploads", "results"):
            folder = server.data_dir / name
            folder.mkdir(exist_ok=True)
            folder.chmod(0o555)
            try:
                ready = client.get("/readyz")
                assert ready.status_code == 503 and ready.json()["status"] == "unwritable"
                assert ready.json()["detail"] == (
                    f"the data folder cannot be written ({folder}): the service's operator "
                    f"must make its data folder (VTRACK_DATA_DIR) {writable}"
                )
                response = submit(client, pets_short, FAST_OPTIONS)
                if name == "uploads":
                    detail = error_of(response, "insufficient_storage")["detail"]
                else:  # the upload is kept; the job fails when its results cannot be written
                    assert response.status_code == 202, response.text
                    job = wait_for_state(client, response.json()["id"], ("succeeded", "failed"))
                    assert job["state"] == "failed"
                    detail = job["error"]
                assert detail.startswith(f"the data folder cannot be written ({folder}"), detail
                assert "Permission denied" in detail and writable in detail
            finally:
                folder.chmod(0o755)
            assert client.get("/readyz").status_code == 200
        # the service goes on
        job_id = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        assert wait_for_state(client, job_id, ("succeeded", "failed"))["state"] == "succeeded"
    assert "Traceback" not in server.log()


def test_a_job_whose_results_cannot_be_removed_is_kept_and_the_reason_given(
    make_server, pets_short
):
    # before: 204, the job's row deleted and its results left behind (no job owned them)
    server = make_server(workers=1, prefix=_as_an_unprivileged_user())
    with server.client() as client:
        job_id = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        wait_for_state(client, job_id, ("succeeded",))
        results = server.data_dir / "results"
        results.chmod(0o555)
        try:
            refused = client.delete(f"/v1/jobs/{job_id}")
            detail = error_of(refused, "insufficient_storage")["detail"]
            assert detail.startswith(f"the data folder cannot be written ({results / job_id}")
            assert client.get(f"/v1/jobs/{job_id}").json()["state"] == "succeeded"  # kept
        finally:
            results.chmod(0o755)
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 204
    assert not (results / job_id).exists()
    assert "Traceback" not in server.log()


def test_a_second_service_on_the_same_data_folder_refuses_to_start(make_server, long_video):
    # Before: it started, logged "jobs interrupted by the last stop: 1 queued again" (false),
    # and took the first one's running job, which began again from frame 0.
    first = make_server(workers=1)
    with first.client() as client:
        job_id = submit(client, long_video, FAST_OPTIONS).json()["id"]
        before = wait_for_frames(client, job_id, 3)["progress"]["frames_done"]
        second = Server(first.data_dir, workers=1)
        try:
            with pytest.raises(RuntimeError, match="exited early"):
                second.start()
        finally:
            second.stop()
        assert second.process.returncode == 2
        refusals = [line for line in second.log().splitlines() if line.startswith(SETTING)]
        assert refusals == [
            f"{SETTING}another vtrack serve uses {first.data_dir} (pid {first.process.pid}): "
            "stop it, or give this one another --data-dir (instances that share "
            "VTRACK_DATABASE_URL share a folder)"
        ]
        assert "queued again" not in first.log()
        status = wait_for_frames(client, job_id, before + 2)  # the first one's job goes on
        assert status["attempts"] == 1
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 202
    # A service that died leaves no lock behind: the kernel released it with the process.
    first.kill()
    third = make_server(data_dir=first.data_dir, workers=1)
    with third.client() as client:
        assert client.get("/readyz").status_code == 200


def test_a_claim_holds_the_folder_until_it_is_released(tmp_path):
    # flock is per open file: a second claim conflicts even from the same process
    settings = Settings(data_dir=tmp_path / "data")
    claim = claim_data_folder(settings)
    try:
        with pytest.raises(DataFolderInUse, match=rf"\(pid {os.getpid()}\): stop it"):
            claim_data_folder(settings)
    finally:
        claim.release()
    claim_data_folder(settings).release()
    assert (tmp_path / "data" / LOCK_NAME).read_text() == f"{os.getpid()}\n"
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == [
        "jobs.sqlite3",
        "results",
        "streams",
        "uploads",
        LOCK_NAME,
    ]


def test_a_data_folder_the_service_creates_is_its_users_alone(tmp_path):
    # it holds footage and people's tracks (before: 0755 under the usual umask, so every user
    # of the machine could read them)
    claim_data_folder(Settings(data_dir=tmp_path / "new" / "data")).release()
    assert stat.S_IMODE((tmp_path / "new" / "data").stat().st_mode) == 0o700
    existing = tmp_path / "shared"
    existing.mkdir(mode=0o750)
    existing.chmod(0o750)  # whatever the umask
    claim_data_folder(Settings(data_dir=existing)).release()
    assert stat.S_IMODE(existing.stat().st_mode) == 0o750  # the operator's choice


def test_a_data_folder_restored_elsewhere_keeps_its_jobs_results(make_server, pets_short, tmp_path):
    # An operator moves the data folder to a bigger disk, or restores a backup to another path.
    first = make_server(tmp_path / "data", workers=1)
    with first.client() as client:
        job_id = submit(client, pets_short, FAST_OPTIONS).json()["id"]
        wait_for_state(client, job_id, ("succeeded",))
        result = client.get(f"/v1/jobs/{job_id}/result?format=json")
        assert result.status_code == 200
    first.stop()
    moved = tmp_path / "bigger disk" / "data"
    moved.mkdir(parents=True)
    # A backup restored elsewhere: the database file and the jobs' folders, without its -wal
    # file. Before, a clean stop left the latest jobs in the -wal file only: the job was
    # unknown (404), and the start's housekeeping deleted its results as no job's.
    shutil.copy2(first.data_dir / "jobs.sqlite3", moved)
    for folder in ("uploads", "results"):
        shutil.copytree(first.data_dir / folder, moved / folder)
    second = make_server(moved, workers=1)
    with second.client() as client:
        # before: 404, "the json result of job ... is gone" (its path named the old folder)
        again = client.get(f"/v1/jobs/{job_id}/result?format=json")
        assert again.status_code == 200, again.text
        assert again.content == result.content
        assert client.delete(f"/v1/jobs/{job_id}").status_code == 204
    assert not (moved / "results" / job_id).exists()  # the moved folder's files are its own


def test_a_disk_with_less_free_space_than_the_setting_is_not_ready(tmp_path):
    # before: /readyz said ready on a full disk, while every upload was refused (507)
    server = Server(tmp_path / "data", workers=1, min_free_mb=10**12).start(ready=False)
    try:
        with server.client() as client:
            wait_for(lambda: client.get("/readyz").json()["workers_ready"] == 1, 60, "a worker")
            ready = client.get("/readyz")
            assert ready.status_code == 503 and ready.json()["status"] == "full"
            detail = ready.json()["detail"]
            assert re.fullmatch(
                r"the data folder's disk has \d+ MB free, under VTRACK_MIN_FREE_MB \(1e\+12\): "
                r"the service's operator must free space in its data folder \(VTRACK_DATA_DIR\)",
                detail,
            ), detail
    finally:
        server.stop()
