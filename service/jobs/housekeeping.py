"""What finished jobs no longer need goes away, so a long-running service does not fill its disk.

- A finished job (succeeded, failed or cancelled) never reads its video again: its upload is
  removed; its results stay.
- With ``VTRACK_RETENTION_HOURS``, a job that finished longer ago than that is deleted with its
  results, as ``DELETE /v1/jobs/{id}`` deletes it; so is a stream's recording finished longer
  ago than that (running and stopped streams alike: recordings hold the cameras' footage).
- When the service starts, uploads and result folders that no job owns (an upload cut by a
  crash, a deletion cut between the job and its files) are removed too. Only then: while the
  service runs, an upload exists a moment before its job does. So are the partial results
  that jobs' attempts left when a service stopped or died while they ran
  (:meth:`service.jobs.files.JobFiles.tidy`; while the service runs, the runner and the
  worker supervisor remove them as attempts end).

The service sweeps when it starts and then every ``VTRACK_HOUSEKEEPING_INTERVAL`` seconds.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass

from service.jobs.files import JobFiles
from service.jobs.store import JobRecord, JobStore
from service.settings import Settings

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Swept:
    """What one sweep removed."""

    uploads: int = 0
    jobs: int = 0
    recordings: int = 0


def remove_job(files: JobFiles, store: JobStore, record: JobRecord) -> None:
    """Delete a finished job with its upload and results.

    The files go first: on a full disk they make the room the database needs to delete the
    row, and a deletion cut in between leaves a job whose results are gone (deleted again
    by the next request), never results that no job owns. Raises ``OSError`` when a file
    cannot be removed (a folder made read-only), the job then kept.
    """
    files.remove(record)
    store.delete(record.id)


def sweep(settings: Settings, store: JobStore, files: JobFiles, *, orphans: bool = False) -> Swept:
    """Remove finished jobs' uploads, jobs past the retention and, with ``orphans``, uploads
    that no job owns (only safe before uploads are accepted) and the partial results of
    attempts that are over. Each deleted job is logged by id; result folders that no job owns
    are named in a warning and kept."""
    jobs = recordings = 0
    if settings.retention_hours is not None:
        now = time.time()
        recordings = _expire_recordings(settings, now - settings.retention_hours * 3600)
        for expired in store.finished_before(now - settings.retention_hours * 3600):
            try:
                remove_job(files, store, expired)
            except OSError as error:  # the others go on; this one is tried again next time
                log.warning("housekeeping: job %s could not be deleted: %s", expired.id, error)
                continue
            jobs += 1
            log.info(
                "housekeeping: job %s (%s %.1f h ago) deleted with its files "
                "(VTRACK_RETENTION_HOURS=%g)",
                expired.id,
                expired.state.value,
                (now - (expired.finished_at or now)) / 3600,
                settings.retention_hours,
            )
    uploads = strays = 0
    for name in files.uploads():
        record = store.get(name.split(".", 1)[0])
        # on shared storage an upload without a job may be another instance's, arriving:
        # only one untouched for a while is no one's
        stray = record is None and orphans and (not store.shared or _untouched(files, name))
        if stray or (record is not None and record.state.finished):
            files.remove_upload(name)
            uploads += record is not None
            strays += record is None
    unknown: list[str] = []
    for job_id in files.result_folders() if orphans else []:
        record = store.get(job_id)
        if record is None:
            unknown.append(job_id)
        else:
            files.tidy(record)
    if uploads:
        log.info("housekeeping: the uploads of %d finished jobs removed", uploads)
    if strays:
        log.info("housekeeping: %d uploads that no job owns removed", strays)
    if unknown:
        # Results are never deleted on a guess: the database may be an older copy (restored
        # without its -wal file, or from a backup) that has not seen these jobs.
        log.warning(
            "housekeeping: %d result folders belong to no job in the database (restored from "
            "an older copy?), left in %s: %s",
            len(unknown),
            files.results_location(),
            ", ".join(sorted(unknown)[:10]) + (", ..." if len(unknown) > 10 else ""),
        )
    return Swept(uploads + strays, jobs, recordings)


UNTOUCHED_SECONDS = 600.0
"""An upload written to no more for this long is no upload in progress (uploads that pause
for VTRACK_UPLOAD_IDLE_SECONDS, 60 by default, are cut)."""


def _untouched(files: JobFiles, name: str) -> bool:
    idle = files.upload_idle(name)
    return idle is not None and idle > UNTOUCHED_SECONDS


def _expire_recordings(settings: Settings, cutoff: float) -> int:
    """Delete the streams' recordings finished (last written) before ``cutoff``; a recording
    still being written is a ``.mcap.partial`` and stays."""
    expired = 0
    for pattern in ("*/*.mcap", "*/*.mcap.broken"):  # a broken one holds footage too
        for path in settings.streams_dir.glob(pattern):
            try:
                if path.stat().st_mtime >= cutoff:
                    continue
                path.unlink()
            except FileNotFoundError:  # its worker's record_keep was first
                continue
            expired += 1
            log.info(
                "housekeeping: recording %s of camera %s deleted (VTRACK_RETENTION_HOURS=%g)",
                path.name,
                path.parent.name,
                settings.retention_hours,
            )
    return expired


class Housekeeper:
    """:func:`sweep` on a thread of its own every ``settings.housekeeping_interval`` seconds.

    A thread, not a task on the event loop: :meth:`stop` waits for a sweep in progress, so the
    service never closes the store under one.
    """

    def __init__(self, settings: Settings, store: JobStore, files: JobFiles) -> None:
        self._settings = settings
        self._store = store
        self._files = files
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name="vtrack-housekeeping", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stopping.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._stopping.wait(self._settings.housekeeping_interval):
            try:
                sweep(self._settings, self._store, self._files)
            except Exception:  # a full disk or a locked file must not end the sweeps
                log.exception("housekeeping failed; trying again later")
