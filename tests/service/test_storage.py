"""The sentences for a data folder that cannot take the bytes (service/storage.py)."""

from __future__ import annotations

import errno
import os
import sqlite3

import pytest

from service.storage import FREE_SPACE, storage_problem


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT])
def test_a_full_disk_is_named_with_the_file(code):
    error = OSError(code, "No space left on device", "/data/results/x/tracks.mcap")
    assert storage_problem(error) == (
        "the data folder's disk is full (/data/results/x/tracks.mcap)",
        FREE_SPACE,
    )


def test_a_file_size_limit_is_named():
    found = storage_problem(OSError(errno.EFBIG, "File too large"))
    assert "largest file" in found.problem and found.remedy == FREE_SPACE


def test_a_full_job_database_is_named():
    error = sqlite3.OperationalError("database or disk is full")
    assert storage_problem(error).problem == "the data folder's disk is full (the job database)"


@pytest.mark.parametrize("code", [errno.EACCES, errno.EPERM, errno.EROFS])
def test_a_folder_the_service_may_not_write_is_named_with_what_to_do(code):
    # before: an internal error (500, or "internal error while tracking (PermissionError...)")
    found = storage_problem(OSError(code, os.strerror(code), "/data/uploads/x.receiving"))
    assert found.problem == (
        f"the data folder cannot be written (/data/uploads/x.receiving): {os.strerror(code)}"
    )
    assert found.remedy == (
        "the service's operator must make its data folder (VTRACK_DATA_DIR) writable by the "
        f"user the service runs as (uid {os.geteuid()})"
    )


@pytest.mark.parametrize(
    "error",
    [
        OSError(errno.EIO, "Input/output error"),
        sqlite3.OperationalError("database is locked"),
        ValueError("disk is full"),
    ],
)
def test_other_errors_are_not_storage_problems(error):
    assert storage_problem(error) is None
