"""What to tell a user when the data folder cannot take more bytes.

A full disk is not a fault of the job or of the upload: the answer says so, and what to do,
instead of an internal error. The callers remove what they had written first, which often
frees enough room to record the outcome.
"""

from __future__ import annotations

import errno
import sqlite3

_FULL = {errno.ENOSPC, errno.EDQUOT}

FREE_SPACE = "the service's operator must free space in its data folder (VTRACK_DATA_DIR)"
"""What to do, the same in every answer about a full data folder."""


def storage_problem(error: BaseException) -> str | None:
    """A sentence naming the storage problem behind ``error``; ``None`` for any other error."""
    if isinstance(error, OSError) and error.errno in _FULL | {errno.EFBIG}:
        where = f" ({error.filename})" if error.filename else ""
        if error.errno == errno.EFBIG:
            return (
                f"a file grew beyond the largest file the data folder may hold{where}: its file "
                "system's limit or the service's file-size limit (ulimit -f)"
            )
        return f"the data folder's disk is full{where}"
    if isinstance(error, sqlite3.OperationalError) and "disk is full" in str(error):
        return "the data folder's disk is full (the job database)"
    return None
