"""The data folder a service owns: checked and locked before the service starts.

Everything the service keeps lives in its data folder (``VTRACK_DATA_DIR``): the job database
``jobs.sqlite3``, ``uploads/``, ``results/`` and ``streams/``. A folder the service cannot write
would let it start, say it is ready and fail every upload (SQLite opens a database it cannot
write read-only, without complaint); and two services on one folder would take each other's
running jobs, each believing the other's were interrupted by a stop. So
:func:`claim_data_folder` runs before anything else of the service starts and refuses, with
one sentence, a folder:

- that cannot be created or written, or whose ``uploads/``, ``results/`` or ``streams/`` cannot;
- that another service uses: it holds an exclusive ``flock`` on ``vtrack.lock`` for as long as
  it runs. The kernel releases the lock when the process ends, however it ends, so a crashed
  service never leaves a stale lock behind; the file stays, holding the pid of its last owner;
- whose job database does not open or take a write.

With a shared job database (``VTRACK_DATABASE_URL``) the folder is shared storage that every
instance of the service uses at once: each takes a *shared* lock, so that instances share it
while a service with its own SQLite database (which takes the exclusive lock) cannot join
them, nor they it; the database is reached and written once before the service starts.

A folder it creates is readable by the service's user alone (``0700``): it holds footage and
people's tracks. An existing folder keeps the permissions its operator gave it.
"""

from __future__ import annotations

import errno
import fcntl
import os
import sqlite3
from pathlib import Path

from service.jobs.files import FolderFiles
from service.jobs.store import JobStore
from service.settings import Settings
from service.storage import storage_problem
from tracking.output_paths import output_folder

__all__ = ["LOCK_NAME", "DataFolder", "DataFolderError", "DataFolderInUse", "claim_data_folder"]

LOCK_NAME = "vtrack.lock"
"""The lock file in the data folder; its content is the pid of the service that holds it."""


class DataFolderError(Exception):
    """The data folder cannot serve. The message says why in one sentence; the caller puts the
    name of the setting (``--data-dir, VTRACK_DATA_DIR``) before it."""


class DataFolderInUse(DataFolderError):
    """Another service holds the data folder's lock."""


class JobDatabaseError(DataFolderError):
    """The shared job database (``VTRACK_DATABASE_URL``) cannot be reached or written."""


class DataFolder:
    """A claimed data folder: its lock is held until :meth:`release`, or until the process
    ends (the lock file's descriptor is not inherited by worker processes, so a worker left
    over from a dead service never holds it)."""

    def __init__(self, path: Path, lock_fd: int) -> None:
        self.path = path
        self._lock_fd: int | None = lock_fd

    def release(self) -> None:
        """Give the folder up (closing the descriptor releases the lock); idempotent."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None


def claim_data_folder(settings: Settings) -> DataFolder:
    """Check the data folder of ``settings`` and take its lock (see the module's docstring).

    Raises
    ------
    DataFolderInUse
        Another service holds the lock; the message names its pid when the lock file has it.
    DataFolderError
        The folder, a subfolder or the job database cannot be written; the message names it
        and the reason.
    """
    new = not settings.data_dir.exists()
    folder = _writable_folder(settings.data_dir)
    if new:  # footage and people's tracks: the service's user alone reads them
        folder.chmod(0o700)
    shared = settings.database_url is not None
    lock_fd = _lock(folder, shared)
    claim = DataFolder(folder, lock_fd)
    try:
        # only once the lock is ours: a second service must not touch the first one's files
        files = FolderFiles(settings.data_dir)
        for subfolder in (files.uploads_dir, files.results_dir, settings.streams_dir):
            _writable_folder(subfolder)
        if shared:
            _reachable_database(settings)
        else:
            _writable_database(settings.database_path)
    except BaseException:
        claim.release()
        raise
    return claim


def _writable_folder(path: Path) -> Path:
    try:
        return output_folder(path)
    except OSError as error:  # its message names the folder and the reason
        raise DataFolderError(str(error)) from None


def _lock(folder: Path, shared: bool = False) -> int:
    """The descriptor of the data folder's lock file, locked, with this process's pid in it
    (``shared``: a shared lock, which instances of one shared database take together)."""
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)  # not inheritable (PEP 446)
    except OSError as error:
        raise DataFolderError(f"cannot write its lock file {path}: {error.strerror}") from None
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except OSError as error:
        holder = os.pread(fd, 32, 0).decode(errors="replace").strip()
        os.close(fd)
        if error.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            pid = f" (pid {holder})" if holder.isdigit() else ""
            if shared:
                raise DataFolderInUse(
                    f"a vtrack serve with its own SQLite database uses {folder}{pid}: instances "
                    "of a shared database (VTRACK_DATABASE_URL) need a folder of their own"
                ) from None
            raise DataFolderInUse(
                f"another vtrack serve uses {folder}{pid}: stop it, or give this one another "
                "--data-dir (instances that share VTRACK_DATABASE_URL share a folder)"
            ) from None
        # a file system without locks (some network mounts) cannot keep two services apart
        raise DataFolderError(f"cannot lock {path}: {error.strerror}") from None
    if not shared:  # the pid of the one holder; shared holders are many
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return fd


def _reachable_database(settings: Settings) -> None:
    """Open the shared job database (its schema brought up to date) and make one write."""
    import psycopg

    try:
        store = JobStore(settings.job_database, folder=settings.data_dir)
        try:
            store.count_start()
        finally:
            store.close()
    except (psycopg.Error, RuntimeError) as error:
        # psycopg's first line names the server and the reason, never the password
        raise JobDatabaseError(str(error).strip().splitlines()[0]) from None


def _writable_database(path: Path) -> None:
    """Open the job database (created with its tables when new) and make one committed write."""
    try:
        store = JobStore(path)
        try:
            store.count_start()
        finally:
            store.close()
    except sqlite3.Error as error:
        found = storage_problem(error)
        reason = found.problem if found else str(error)
        name = getattr(error, "sqlite_errorname", "")
        if name.startswith(("SQLITE_READONLY", "SQLITE_CANTOPEN", "SQLITE_PERM")):
            reason += (
                f"; it, its folder, and its -wal and -shm files if there are any, must be "
                f"writable by the user the service runs as (uid {os.geteuid()})"
            )
        raise DataFolderError(f"cannot write the job database {path}: {reason}") from None
