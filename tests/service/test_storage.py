"""The sentences for a data folder that cannot take more bytes (service/storage.py)."""

from __future__ import annotations

import errno
import sqlite3

import pytest

from service.storage import storage_problem


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT])
def test_a_full_disk_is_named_with_the_file(code):
    error = OSError(code, "No space left on device", "/data/results/x/tracks.mcap")
    assert storage_problem(error) == "the data folder's disk is full (/data/results/x/tracks.mcap)"


def test_a_file_size_limit_is_named():
    assert "largest file" in storage_problem(OSError(errno.EFBIG, "File too large"))


def test_a_full_job_database_is_named():
    error = sqlite3.OperationalError("database or disk is full")
    assert storage_problem(error) == "the data folder's disk is full (the job database)"


@pytest.mark.parametrize(
    "error",
    [
        OSError(errno.EACCES, "Permission denied"),
        sqlite3.OperationalError("database is locked"),
        ValueError("disk is full"),
    ],
)
def test_other_errors_are_not_storage_problems(error):
    assert storage_problem(error) is None
