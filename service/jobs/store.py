"""The job store: one SQLite database file (WAL mode) beside the uploads and results.

Accepted jobs survive a restart: the API process writes a job when the upload is accepted,
worker processes claim queued jobs, report progress and finish them, each through its own
connection. Every write a worker makes is fenced by the job's attempt number and the worker's
pid, so a worker left over from a previous service process can never overwrite the state of the
attempt that replaced it.
"""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from api_schemas.jobs import JobState

DURATION_BUCKETS = (1.0, 5.0, 15.0, 60.0, 300.0, 900.0, 3600.0, 14400.0)
"""Upper bounds (seconds) of the job processing-time histogram kept in the counters table."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    options TEXT NOT NULL,
    video_filename TEXT,
    video_path TEXT NOT NULL,
    result_dir TEXT NOT NULL,
    created_at REAL NOT NULL,
    started_at REAL,
    finished_at REAL,
    frames_done INTEGER NOT NULL DEFAULT 0,
    frames_total INTEGER,
    fps REAL,
    error TEXT,
    warnings TEXT NOT NULL DEFAULT '[]',
    results TEXT NOT NULL DEFAULT '{}',
    attempts INTEGER NOT NULL DEFAULT 0,
    stops INTEGER NOT NULL DEFAULT 0,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    worker_pid INTEGER
);
CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs (state, created_at);
CREATE TABLE IF NOT EXISTS counters (name TEXT PRIMARY KEY, value REAL NOT NULL);
"""
_ADDED_COLUMNS = {"stops": "INTEGER NOT NULL DEFAULT 0", "progressed_at": "REAL"}
"""Columns of ``jobs`` newer than the first release, with their definitions: starts a clean
stop of the service ended; when the running attempt last read a frame (or started)."""


_JOB_FILES = ("uploads", "results")
"""The data folder's subfolders holding a job's files, one entry per job: its upload and its
results folder."""


def _portable(path: Path, folder: Path) -> str:
    """How a job's file is stored: ``results/<id>`` for one in the data folder ``folder``, so
    that a data folder moved or restored elsewhere keeps its jobs' files; other paths whole."""
    if path.parent.name in _JOB_FILES and path.parent.parent == folder:
        return f"{path.parent.name}/{path.name}"
    return str(path)


def _located(stored: str, folder: Path) -> Path:
    """Where a job's file stored as ``stored`` is in the data folder ``folder``. Earlier
    versions stored the whole path as the service then saw it (absolute, or relative to its
    working folder): read by its last two parts, it is found wherever the folder is now."""
    path = Path(stored)
    if path.parent.name in _JOB_FILES:
        return folder / path.parent.name / path.name
    return path


@dataclass(frozen=True, slots=True)
class JobRecord:
    """One row of the jobs table."""

    id: str
    state: JobState
    options: dict[str, Any]
    video_filename: str | None
    video_path: Path
    result_dir: Path
    created_at: float
    started_at: float | None
    finished_at: float | None
    frames_done: int
    frames_total: int | None
    fps: float | None
    error: str | None
    warnings: list[str] = field(default_factory=list)
    results: dict[str, str] = field(default_factory=dict)
    attempts: int = 0
    cancel_requested: bool = False
    worker_pid: int | None = None
    progressed_at: float | None = None

    @classmethod
    def from_row(cls, row: sqlite3.Row, folder: Path) -> JobRecord:
        """The record of ``row`` in the database of the data folder ``folder``."""
        return cls(
            id=row["id"],
            state=JobState(row["state"]),
            options=json.loads(row["options"]),
            video_filename=row["video_filename"],
            video_path=_located(row["video_path"], folder),
            result_dir=_located(row["result_dir"], folder),
            created_at=row["created_at"],
            started_at=row["started_at"],
            finished_at=row["finished_at"],
            frames_done=row["frames_done"],
            frames_total=row["frames_total"],
            fps=row["fps"],
            error=row["error"],
            warnings=json.loads(row["warnings"]),
            results=json.loads(row["results"]),
            attempts=row["attempts"],
            cancel_requested=bool(row["cancel_requested"]),
            worker_pid=row["worker_pid"],
            progressed_at=row["progressed_at"],
        )


class JobStore:
    """Jobs in a SQLite file. Safe to share between threads of one process; every process
    (the API, each worker) opens its own."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.folder = self.path.parent  # the data folder, which job files are stored within
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._db = sqlite3.connect(
            self.path, timeout=30.0, isolation_level=None, check_same_thread=False
        )
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.execute("PRAGMA busy_timeout=30000")
        self._db.execute("PRAGMA secure_delete=ON")  # see delete()
        with self._lock:
            self._db.executescript(_SCHEMA)
            self._add_missing_columns()

    def _add_missing_columns(self) -> None:
        """Columns added since a data folder's database was created (it keeps its jobs)."""
        have = {row["name"] for row in self._db.execute("PRAGMA table_info(jobs)")}
        for name, definition in _ADDED_COLUMNS.items():
            if name not in have:
                with suppress(sqlite3.OperationalError):  # another process's race
                    self._db.execute(f"ALTER TABLE jobs ADD COLUMN {name} {definition}")

    def close(self) -> None:
        """Close the database; its write-ahead log moved into the database file first, so that
        after a clean stop ``jobs.sqlite3`` alone holds every job (a copy or backup of it
        misses nothing). Best effort: a process still reading keeps its part of the log."""
        with self._lock:
            with suppress(sqlite3.Error):
                self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
            self._db.close()

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """A write transaction that takes the database lock at once (no upgrade deadlocks)."""
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    # -- reads ---------------------------------------------------------------------------------

    def get(self, job_id: str) -> JobRecord | None:
        with self._lock:
            row = self._db.execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        return JobRecord.from_row(row, self.folder) if row else None

    def list(
        self,
        limit: int = 100,
        state: JobState | None = None,
        before: str | None = None,
        finished_after: float | None = None,
    ) -> list[JobRecord]:
        """Newest first; with ``before``, only jobs older than that job (a page after it); with
        ``finished_after`` (Unix time), only jobs finished after it.

        Raises
        ------
        KeyError
            ``before`` names no job.
        """
        where, args = [], []
        if state is not None:
            where.append("state = ?")
            args.append(state.value)
        if finished_after is not None:
            # to the microsecond, as finished_at is shown: a client that asks from a job's
            # finished_at must not get that job again
            where.append("round(finished_at, 6) > ?")
            args.append(round(finished_after, 6))
        with self._lock:
            if before is not None:
                row = self._db.execute(
                    "SELECT created_at, rowid FROM jobs WHERE id = ?", (before,)
                ).fetchone()
                if row is None:
                    raise KeyError(before)
                where.append("(created_at < ? OR (created_at = ? AND rowid < ?))")
                args += [row[0], row[0], row[1]]
            query = "SELECT * FROM jobs" + (" WHERE " + " AND ".join(where) if where else "")
            query += " ORDER BY created_at DESC, rowid DESC LIMIT ?"
            rows = self._db.execute(query, (*args, limit)).fetchall()
        return [JobRecord.from_row(row, self.folder) for row in rows]

    def queued_ahead(self, record: JobRecord) -> int | None:
        """Queued jobs that :meth:`claim` takes before ``record``; None unless it is queued."""
        if record.state != JobState.queued:
            return None
        # a count on the (state, created_at) index: every event follower asks this four times
        # a second, and reading the whole queue each time grew with the queue
        with self._lock:
            (count,) = self._db.execute(
                "SELECT count(*) FROM jobs WHERE state = ? AND (created_at < ? OR "
                "(created_at = ? AND rowid < (SELECT rowid FROM jobs WHERE id = ?)))",
                (JobState.queued.value, record.created_at, record.created_at, record.id),
            ).fetchone()
        return count

    def queue_positions(self) -> dict[str, int]:
        """Each queued job's place in the queue, 0 for the one :meth:`claim` takes next, in
        the order :meth:`queued_ahead` counts (one query for a whole page of a listing)."""
        with self._lock:
            rows = self._db.execute(
                "SELECT id FROM jobs WHERE state = ? ORDER BY created_at, rowid",
                (JobState.queued.value,),
            ).fetchall()
        return {row[0]: place for place, row in enumerate(rows)}

    def running(self) -> list[JobRecord]:
        return self.list(limit=1_000_000, state=JobState.running)

    def finished_before(self, cutoff: float) -> list[JobRecord]:
        """Jobs that finished (succeeded, failed, cancelled) before ``cutoff`` (epoch seconds)."""
        ended = [state.value for state in JobState if state.finished]
        marks = ", ".join("?" * len(ended))
        with self._lock:
            rows = self._db.execute(
                f"SELECT * FROM jobs WHERE state IN ({marks}) AND finished_at < ?",
                (*ended, cutoff),
            ).fetchall()
        return [JobRecord.from_row(row, self.folder) for row in rows]

    def counts_by_state(self) -> dict[JobState, int]:
        with self._lock:
            rows = self._db.execute("SELECT state, COUNT(*) FROM jobs GROUP BY state").fetchall()
        counts = dict.fromkeys(JobState, 0)
        counts.update({JobState(state): n for state, n in rows})
        return counts

    def waits(self) -> tuple[float | None, float | None]:
        """When the oldest queued job was created, and the earliest time a running job last
        read a frame (or started): what waits longest, for the metrics. ``None``: no such job."""
        with self._lock:
            row = self._db.execute(
                "SELECT MIN(CASE WHEN state = ? THEN created_at END),"
                " MIN(CASE WHEN state = ? THEN COALESCE(progressed_at, started_at) END)"
                " FROM jobs WHERE state IN (?, ?)",
                (JobState.queued.value, JobState.running.value) * 2,
            ).fetchone()
        return row[0], row[1]

    def counters(self) -> dict[str, float]:
        with self._lock:
            rows = self._db.execute("SELECT name, value FROM counters").fetchall()
        return {name: value for name, value in rows}

    # -- the API's writes ----------------------------------------------------------------------

    def count_start(self) -> None:
        """Count one start of the service (counter ``service_starts``).

        A real write, made before the service answers: SQLite opens a database this process
        cannot write (another user's file or ``-wal`` file, a read-only mount) read-only and
        without complaint, and only a write shows it.
        """
        with self._transaction():
            self._add_counter("service_starts", 1)

    def create(
        self,
        job_id: str,
        options: dict[str, Any],
        video_path: Path,
        result_dir: Path,
        video_filename: str | None = None,
        frames_total: int | None = None,
    ) -> JobRecord:
        with self._lock:
            self._db.execute(
                "INSERT INTO jobs (id, state, options, video_filename, video_path, result_dir,"
                " created_at, frames_total) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    job_id,
                    JobState.queued.value,
                    json.dumps(options),
                    video_filename,
                    _portable(video_path, self.folder),
                    _portable(result_dir, self.folder),
                    time.time(),
                    frames_total,
                ),
            )
        record = self.get(job_id)
        if record is None:  # pragma: no cover - the insert just happened
            raise RuntimeError(f"job {job_id} vanished after its insert")
        return record

    def request_cancel(self, job_id: str) -> JobState | None:
        """Cancel a queued job at once, or ask a running one to stop; returns the new state
        (``running`` until its worker stops), ``None`` for an unknown job."""
        with self._transaction() as db:
            row = db.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
            if row is None:
                return None
            state = JobState(row[0])
            if state == JobState.queued:
                db.execute(
                    "UPDATE jobs SET state = ?, finished_at = ?, cancel_requested = 1,"
                    " error = 'cancelled before it started' WHERE id = ?",
                    (JobState.cancelled.value, time.time(), job_id),
                )
                self._count_finished(JobState.cancelled, job_id)
                state = JobState.cancelled
            elif state == JobState.running:
                db.execute("UPDATE jobs SET cancel_requested = 1 WHERE id = ?", (job_id,))
            return state

    def delete(self, job_id: str) -> bool:
        """Delete the job's row, leaving no copy of it in the database's files: its client's
        file name is personal data. ``secure_delete`` zeroes the freed bytes in the database;
        the write-ahead log still holds the pages the row was written in until a checkpoint
        moves them into the database and empties the log."""
        with self._lock:
            cursor = self._db.execute("DELETE FROM jobs WHERE id = ?", (job_id,))
            # as far as no reader still needs the log: a worker's open read is rare and short,
            # and the next deletion empties what it kept
            self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
        return cursor.rowcount > 0

    def requeue_orphans(self, max_attempts: int) -> tuple[list[str], list[str]]:
        """Jobs left running by a service that died: queued again, or failed once a service
        has died under them ``max_attempts`` times (a job that takes the service down with it
        must not do so forever). Starts that a clean stop ended do not count: a job survives
        any number of restarts. Call before any worker of this service starts."""
        requeued, failed = [], []
        with self._transaction() as db:
            rows = db.execute(
                "SELECT id, attempts - stops FROM jobs WHERE state = ?", (JobState.running.value,)
            ).fetchall()
            for job_id, deaths in rows:
                if deaths >= max_attempts:
                    db.execute(
                        "UPDATE jobs SET state = ?, finished_at = ?, error = ?,"
                        " worker_pid = NULL WHERE id = ?",
                        (
                            JobState.failed.value,
                            time.time(),
                            f"the service died while this job ran, {_times(deaths)}; "
                            "it is not started again",
                            job_id,
                        ),
                    )
                    self._count_finished(JobState.failed, job_id)
                    failed.append(job_id)
                else:
                    db.execute(
                        "UPDATE jobs SET state = ?, worker_pid = NULL, frames_done = 0,"
                        " fps = NULL WHERE id = ?",
                        (JobState.queued.value, job_id),
                    )
                    requeued.append(job_id)
        return requeued, failed

    def fail_running(self, job_id: str, reason: str, worker_pid: int | None = None) -> bool:
        """Fail a running job from outside its worker (crash, time limit)."""
        query = "UPDATE jobs SET state = ?, finished_at = ?, error = ? WHERE id = ? AND state = ?"
        args: tuple[Any, ...] = (
            JobState.failed.value,
            time.time(),
            reason,
            job_id,
            JobState.running.value,
        )
        if worker_pid is not None:
            query += " AND worker_pid = ?"
            args = (*args, worker_pid)
        with self._lock:
            cursor = self._db.execute(query, args)
            if cursor.rowcount:
                self._count_finished(JobState.failed, job_id)
        return cursor.rowcount > 0

    def requeue_dead(self, job_id: str, worker_pid: int, max_attempts: int) -> JobState | None:
        """A running job whose worker died with the fork server (the OOM killer's usual victim
        besides the workers): queued again, and the start counted as a death, as
        :meth:`requeue_orphans` counts a service's; failed once it has died ``max_attempts``
        times. Returns the job's new state, ``None`` if ``worker_pid`` no longer runs it."""
        with self._transaction() as db:
            row = db.execute(
                "SELECT attempts - stops FROM jobs WHERE id = ? AND state = ? AND worker_pid = ?",
                (job_id, JobState.running.value, worker_pid),
            ).fetchone()
            if row is None:
                return None
            if row[0] >= max_attempts:
                db.execute(
                    "UPDATE jobs SET state = ?, finished_at = ?, error = ?, worker_pid = NULL"
                    " WHERE id = ?",
                    (
                        JobState.failed.value,
                        time.time(),
                        f"the service's fork server died while this job ran, {_times(row[0])}; "
                        "it is not started again",
                        job_id,
                    ),
                )
                self._count_finished(JobState.failed, job_id)
                return JobState.failed
            db.execute(
                "UPDATE jobs SET state = ?, worker_pid = NULL, frames_done = 0, fps = NULL"
                " WHERE id = ?",
                (JobState.queued.value, job_id),
            )
            return JobState.queued

    def requeue_running(self, job_id: str, worker_pid: int) -> bool:
        """Put a job back in the queue (its worker was stopped by a clean shutdown); the start
        does not count against ``max_attempts``."""
        with self._lock:
            cursor = self._db.execute(
                "UPDATE jobs SET state = ?, worker_pid = NULL, frames_done = 0, fps = NULL,"
                " stops = stops + 1 WHERE id = ? AND state = ? AND worker_pid = ?",
                (JobState.queued.value, job_id, JobState.running.value, worker_pid),
            )
        return cursor.rowcount > 0

    # -- a worker's writes ---------------------------------------------------------------------

    def claim(self, worker_pid: int) -> JobRecord | None:
        """Take the oldest queued job: it becomes running, attempted once more, owned by
        ``worker_pid``."""
        with self._transaction() as db:
            row = db.execute(
                "SELECT id FROM jobs WHERE state = ? ORDER BY created_at, rowid LIMIT 1",
                (JobState.queued.value,),
            ).fetchone()
            if row is None:
                return None
            now = time.time()
            db.execute(
                "UPDATE jobs SET state = ?, started_at = ?, progressed_at = ?,"
                " attempts = attempts + 1, worker_pid = ?, frames_done = 0, fps = NULL"
                " WHERE id = ?",
                (JobState.running.value, now, now, worker_pid, row[0]),
            )
        return self.get(row[0])

    def report_progress(
        self, job: JobRecord, worker_pid: int, frames_done: int, fps: float | None, new_frames: int
    ) -> bool:
        """Record progress; ``False`` when the job is no longer this attempt's or is to stop
        (cancelled, failed from outside, requeued). A report with more frames read than the
        last one moves ``progressed_at`` (the supervisor's stall limit reads it)."""
        with self._transaction() as db:
            cursor = db.execute(
                "UPDATE jobs SET progressed_at = CASE WHEN frames_done = ? THEN progressed_at"
                " ELSE ? END, frames_done = ?, fps = ? WHERE id = ? AND attempts = ?"
                " AND worker_pid = ? AND state = ? AND cancel_requested = 0",
                (frames_done, time.time(), frames_done, fps, job.id, job.attempts, worker_pid,
                 JobState.running.value),
            )  # fmt: skip
            if cursor.rowcount and new_frames:
                self._add_counter("frames_processed", new_frames)
        return cursor.rowcount > 0

    def cancel_requested(self, job_id: str) -> bool:
        with self._lock:
            row = self._db.execute(
                "SELECT cancel_requested FROM jobs WHERE id = ?", (job_id,)
            ).fetchone()
        return row is None or bool(row[0])

    def finish(
        self,
        job: JobRecord,
        worker_pid: int,
        state: JobState,
        *,
        error: str | None = None,
        results: dict[str, str] | None = None,
        warnings: list[str] | None = None,
        frames_total: int | None = None,
    ) -> bool:
        """End the worker's attempt; ``False`` when the job was no longer its own."""
        with self._transaction() as db:
            cursor = db.execute(
                "UPDATE jobs SET state = ?, finished_at = ?, error = ?, results = ?, warnings = ?,"
                " frames_total = COALESCE(?, frames_total) WHERE id = ? AND attempts = ?"
                " AND worker_pid = ? AND state = ?",
                (
                    state.value,
                    time.time(),
                    error,
                    json.dumps(results or {}),
                    json.dumps(warnings or []),
                    frames_total,
                    job.id,
                    job.attempts,
                    worker_pid,
                    JobState.running.value,
                ),
            )
            if cursor.rowcount:
                self._count_finished(state, job.id)
        return cursor.rowcount > 0

    # -- counters ------------------------------------------------------------------------------

    def _count_finished(self, state: JobState, job_id: str) -> None:
        row = self._db.execute(
            "SELECT started_at, finished_at FROM jobs WHERE id = ?", (job_id,)
        ).fetchone()
        self._add_counter(f"jobs_{state.value}", 1)
        if row and row[0] and row[1]:
            seconds = row[1] - row[0]
            self._add_counter("processing_seconds", seconds)
            self._add_counter("processing_count", 1)
            for bound in DURATION_BUCKETS:
                if seconds <= bound:
                    self._add_counter(f"processing_le_{bound:g}", 1)

    def _add_counter(self, name: str, delta: float) -> None:
        self._db.execute(
            "INSERT INTO counters (name, value) VALUES (?, ?)"
            " ON CONFLICT (name) DO UPDATE SET value = value + excluded.value",
            (name, delta),
        )


def _times(count: int) -> str:
    """``once``, ``twice``, ``3 times``."""
    return {1: "once", 2: "twice"}.get(count, f"{count} times")
