"""What to tell a user when the data folder cannot take the bytes: full, or not writable.

Neither is a fault of the job or of the upload: the answer says so, and what the operator must
do, instead of an internal error. The callers remove what they had written first, which often
frees enough room (on a full disk) to record the outcome.
"""

from __future__ import annotations

import errno
import os
import sqlite3
from typing import NamedTuple

_FULL = {errno.ENOSPC, errno.EDQUOT}
_DENIED = {errno.EACCES, errno.EPERM, errno.EROFS}

FREE_SPACE = "the service's operator must free space in its data folder (VTRACK_DATA_DIR)"
"""What to do, the same in every answer about a full data folder."""


def writable_remedy() -> str:
    """What to do about a data folder the service may not write."""
    return (
        "the service's operator must make its data folder (VTRACK_DATA_DIR) writable by the "
        f"user the service runs as (uid {os.geteuid()})"
    )


class StorageProblem(NamedTuple):
    """What keeps the data folder from taking the bytes, and what the operator must do."""

    problem: str
    remedy: str


def storage_problem(error: BaseException) -> StorageProblem | None:
    """The storage problem behind ``error``; ``None`` for any other error."""
    if isinstance(error, sqlite3.OperationalError) and "disk is full" in str(error):
        return StorageProblem("the data folder's disk is full (the job database)", FREE_SPACE)
    if not isinstance(error, OSError):
        return None
    where = f" ({error.filename})" if error.filename else ""
    if error.errno in _FULL:
        return StorageProblem(f"the data folder's disk is full{where}", FREE_SPACE)
    if error.errno == errno.EFBIG:
        return StorageProblem(
            f"a file grew beyond the largest file the data folder may hold{where}: its file "
            "system's limit or the service's file-size limit (ulimit -f)",
            FREE_SPACE,
        )
    if error.errno in _DENIED:
        return StorageProblem(
            f"the data folder cannot be written{where}: {os.strerror(error.errno)}",
            writable_remedy(),
        )
    return None


def free_bytes(folder: os.PathLike[str] | str) -> int:
    """Bytes the service may still write on ``folder``'s file system (as an unprivileged
    user: the blocks kept for root do not count)."""
    stats = os.statvfs(folder)
    return stats.f_bavail * stats.f_frsize
