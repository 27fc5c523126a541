"""The job store: one SQLite database file (WAL mode) beside the uploads and results, or a
PostgreSQL database that many service instances share (:mod:`service.jobs.database`).

Accepted jobs survive a restart: the API process writes a job when the upload is accepted,
worker processes claim queued jobs, report progress and finish them, each through its own
connection. Every write a worker makes is fenced by the job's attempt number and the worker's
pid, so a worker left over from a previous service process can never overwrite the state of the
attempt that replaced it.
"""

from __future__ import annotations

import builtins
import json
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from api_schemas.analytics import AnalyticsCounts
from api_schemas.jobs import JobState
from service.delivery.messages import job_summary
from service.delivery.outbox import OUTBOX_SCHEMA, queue_events
from service.jobs.database import Row, Statements, open_database
from service.jobs.files import FolderFiles

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
_ADDED_COLUMNS = {
    "stops": "INTEGER NOT NULL DEFAULT 0",
    "progressed_at": "REAL",
    "instance": "TEXT",
    "lease_until": "REAL",
}
"""Columns of ``jobs`` newer than the first release, with their definitions: starts a clean
stop of the service ended; when the running attempt last read a frame (or started); the
service instance whose worker runs the job, and until when its claim holds unless renewed."""


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
    instance: str | None = None
    """The service instance whose worker runs the job (a shared database's)."""

    @classmethod
    def from_row(cls, row: Row, files: FolderFiles) -> JobRecord:
        """The record of ``row`` in the database of the job files ``files``."""
        return cls(
            id=row["id"],
            state=JobState(row["state"]),
            options=json.loads(row["options"]),
            video_filename=row["video_filename"],
            video_path=files.located(row["video_path"]),
            result_dir=files.located(row["result_dir"]),
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
            instance=row.get("instance"),
        )


class JobStore:
    """Jobs in a SQLite file or a PostgreSQL database. Safe to share between threads of one
    process; every process (the API, each worker) opens its own.

    Parameters
    ----------
    where:
        The SQLite file (``jobs.sqlite3`` of the data folder), or a ``postgresql://`` URL.
    folder:
        The data folder, which job files are stored relative to (default: the SQLite file's).
    sinks:
        The sinks told of every job that ends, however it ends: its summary is queued in the
        outbox in the transaction that ends it (:func:`_ended`).
    """

    def __init__(
        self, where: str | Path, folder: Path | None = None, sinks: Sequence[str] = ()
    ) -> None:
        self._db = open_database(where)
        self._sinks = tuple(sinks)
        """The sinks (webhooks, the MQTT broker) that hear of every job that ends."""
        self.path: Path | None = None if self.shared else Path(where)
        """The SQLite file (None for a PostgreSQL database)."""
        self.folder = folder if folder is not None else Path(where).parent
        self._files = FolderFiles(self.folder)
        self._db.migrate(_SCHEMA, _ADDED_COLUMNS)
        self._db.migrate(OUTBOX_SCHEMA)  # the summaries of finished jobs go out through it

    @property
    def shared(self) -> bool:
        """Whether other service instances may use this database (PostgreSQL)."""
        return self._db.order == "seq"

    def close(self) -> None:
        """Close the database (SQLite: its write-ahead log moved into the file first)."""
        self._db.close()

    def wait_for_work(self, timeout: float) -> None:
        """An idle worker's wait: ``timeout`` seconds, or less when a job is queued."""
        self._db.wait_for_work(timeout)

    # -- reads ---------------------------------------------------------------------------------

    def get(self, job_id: str) -> JobRecord | None:
        row = self._db.one("SELECT * FROM jobs WHERE id = ?", (job_id,))
        return JobRecord.from_row(row, self._files) if row else None

    def list(
        self,
        limit: int = 100,
        state: JobState | None = None,
        before: str | None = None,
        finished_after: float | None = None,
    ) -> builtins.list[JobRecord]:
        """Newest first; with ``before``, only jobs older than that job (a page after it); with
        ``finished_after`` (Unix time), only jobs finished after it.

        Raises
        ------
        KeyError
            ``before`` names no job.
        """
        order = self._db.order
        where: list[str] = []
        args: list[Any] = []
        if state is not None:
            where.append("state = ?")
            args.append(state.value)
        if finished_after is not None:
            # to the microsecond, as finished_at is shown: a client that asks from a job's
            # finished_at must not get that job again
            where.append(f"{self._db.rounded('finished_at', 6)} > ?")
            args.append(round(finished_after, 6))
        if before is not None:
            row = self._db.one(
                f"SELECT created_at, {order} AS place FROM jobs WHERE id = ?", (before,)
            )
            if row is None:
                raise KeyError(before)
            where.append(f"(created_at < ? OR (created_at = ? AND {order} < ?))")
            args += [row["created_at"], row["created_at"], row["place"]]
        query = "SELECT * FROM jobs" + (" WHERE " + " AND ".join(where) if where else "")
        query += f" ORDER BY created_at DESC, {order} DESC LIMIT ?"
        rows = self._db.all(query, (*args, limit))
        return [JobRecord.from_row(row, self._files) for row in rows]

    def queued_ahead(self, record: JobRecord) -> int | None:
        """Queued jobs that :meth:`claim` takes before ``record``; None unless it is queued."""
        if record.state != JobState.queued:
            return None
        # a count on the (state, created_at) index: every event follower asks this four times
        # a second, and reading the whole queue each time grew with the queue
        order = self._db.order
        row = self._db.one(
            "SELECT count(*) AS ahead FROM jobs WHERE state = ? AND (created_at < ? OR "
            f"(created_at = ? AND {order} < (SELECT {order} FROM jobs WHERE id = ?)))",
            (JobState.queued.value, record.created_at, record.created_at, record.id),
        )
        return row["ahead"] if row else 0

    def queue_positions(self) -> dict[str, int]:
        """Each queued job's place in the queue, 0 for the one :meth:`claim` takes next, in
        the order :meth:`queued_ahead` counts (one query for a whole page of a listing)."""
        rows = self._db.all(
            f"SELECT id FROM jobs WHERE state = ? ORDER BY created_at, {self._db.order}",
            (JobState.queued.value,),
        )
        return {row["id"]: place for place, row in enumerate(rows)}

    def running(self, instance: str | None = None) -> builtins.list[JobRecord]:
        """Running jobs; with ``instance``, only those its workers run."""
        jobs = self.list(limit=1_000_000, state=JobState.running)
        return [job for job in jobs if instance is None or job.instance == instance]

    def finished_before(self, cutoff: float) -> builtins.list[JobRecord]:
        """Jobs that finished (succeeded, failed, cancelled) before ``cutoff`` (epoch seconds)."""
        ended = [state.value for state in JobState if state.finished]
        marks = ", ".join("?" * len(ended))
        rows = self._db.all(
            f"SELECT * FROM jobs WHERE state IN ({marks}) AND finished_at < ?", (*ended, cutoff)
        )
        return [JobRecord.from_row(row, self._files) for row in rows]

    def counts_by_state(self) -> dict[JobState, int]:
        rows = self._db.all("SELECT state, COUNT(*) AS n FROM jobs GROUP BY state")
        counts = dict.fromkeys(JobState, 0)
        counts.update({JobState(row["state"]): row["n"] for row in rows})
        return counts

    def waits(self) -> tuple[float | None, float | None]:
        """When the oldest queued job was created, and the earliest time a running job last
        read a frame (or started): what waits longest, for the metrics. ``None``: no such job."""
        row = self._db.one(
            "SELECT MIN(CASE WHEN state = ? THEN created_at END) AS queued,"
            " MIN(CASE WHEN state = ? THEN COALESCE(progressed_at, started_at) END) AS running"
            " FROM jobs WHERE state IN (?, ?)",
            (JobState.queued.value, JobState.running.value) * 2,
        )
        return (row["queued"], row["running"]) if row else (None, None)

    def counters(self) -> dict[str, float]:
        return {row["name"]: row["value"] for row in self._db.all("SELECT * FROM counters")}

    # -- the API's writes ----------------------------------------------------------------------

    def count_start(self) -> None:
        """Count one start of the service (counter ``service_starts``).

        A real write, made before the service answers: SQLite opens a database this process
        cannot write (another user's file or ``-wal`` file, a read-only mount) read-only and
        without complaint, and only a write shows it.
        """
        with self._db.transaction() as db:
            _add_counter(db, "service_starts", 1)

    def create(
        self,
        job_id: str,
        options: dict[str, Any],
        video_path: Path,
        result_dir: Path,
        video_filename: str | None = None,
        frames_total: int | None = None,
    ) -> JobRecord:
        self._db.run(
            "INSERT INTO jobs (id, state, options, video_filename, video_path, result_dir,"
            " created_at, frames_total) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            (
                job_id,
                JobState.queued.value,
                json.dumps(options),
                video_filename,
                self._files.portable(video_path),
                self._files.portable(result_dir),
                time.time(),
                frames_total,
            ),
        )
        self._db.notify_queued()
        record = self.get(job_id)
        if record is None:  # pragma: no cover - the insert just happened
            raise RuntimeError(f"job {job_id} vanished after its insert")
        return record

    def request_cancel(self, job_id: str) -> JobState | None:
        """Cancel a queued job at once, or ask a running one to stop; returns the new state
        (``running`` until its worker stops), ``None`` for an unknown job."""
        with self._db.transaction() as db:
            row = db.one(f"SELECT state FROM jobs WHERE id = ?{self._db.lock_rows}", (job_id,))
            if row is None:
                return None
            state = JobState(row["state"])
            if state == JobState.queued:
                db.run(
                    "UPDATE jobs SET state = ?, finished_at = ?, cancel_requested = 1,"
                    " error = 'cancelled before it started' WHERE id = ?",
                    (JobState.cancelled.value, time.time(), job_id),
                )
                _ended(db, JobState.cancelled, job_id, self._sinks)
                state = JobState.cancelled
            elif state == JobState.running:
                db.run("UPDATE jobs SET cancel_requested = 1 WHERE id = ?", (job_id,))
            return state

    def delete(self, job_id: str) -> bool:
        """Delete the job's row, leaving no copy of it in the database's files: its client's
        file name is personal data. SQLite's ``secure_delete`` zeroes the freed bytes in the
        database; the write-ahead log still holds the pages the row was written in until a
        checkpoint moves them into the database and empties the log."""
        deleted = self._db.run("DELETE FROM jobs WHERE id = ?", (job_id,))
        self._db.checkpoint()
        return deleted > 0

    def requeue_orphans(
        self, max_attempts: int, instance: str | None = None
    ) -> tuple[builtins.list[str], builtins.list[str]]:
        """Jobs left running by a service that died: queued again, or failed once a service
        has died under them ``max_attempts`` times (a job that takes the service down with it
        must not do so forever). Starts that a clean stop ended do not count: a job survives
        any number of restarts. Call before any worker of this service starts.

        On a shared database the running jobs may be other instances' and alive: only those
        whose lease ran out are taken (:meth:`requeue_expired`), and those of ``instance``,
        this one's name, which an earlier process of it left (its renewals would otherwise
        keep them running for ever: a restart within a lease found them unexpired)."""
        if self.shared:
            own = self._requeue_dead_starts(
                "state = ? AND instance = ?",
                (JobState.running.value, instance),
                max_attempts,
                "the service instance running it was lost",
            )
            expired = self.requeue_expired(max_attempts)
            return own[0] + expired[0], own[1] + expired[1]
        return self._requeue_dead_starts(
            "state = ?", (JobState.running.value,), max_attempts, "the service died"
        )

    def requeue_expired(self, max_attempts: int) -> tuple[builtins.list[str], builtins.list[str]]:
        """Running jobs whose instance stopped renewing their lease (:meth:`renew_leases`):
        its machine died or lost the database. As :meth:`requeue_orphans`, counted as a death
        of the job's start."""
        return self._requeue_dead_starts(
            "state = ? AND lease_until < ?",
            (JobState.running.value, time.time()),
            max_attempts,
            "the service instance running it was lost",
        )

    def _requeue_dead_starts(
        self, where: str, args: tuple[Any, ...], max_attempts: int, what: str
    ) -> tuple[builtins.list[str], builtins.list[str]]:
        requeued, failed = [], []
        with self._db.transaction() as db:
            rows = db.all(
                f"SELECT id, attempts - stops AS deaths FROM jobs WHERE {where}"
                f"{self._db.skip_locked}",
                args,
            )
            for row in rows:
                job_id, deaths = row["id"], row["deaths"]
                if deaths >= max_attempts:
                    _fail(db, job_id, f"{what} while this job ran, {_times(deaths)}", self._sinks)
                    failed.append(job_id)
                else:
                    _queue_again(db, job_id)
                    requeued.append(job_id)
        if requeued:
            self._db.notify_queued()
        return requeued, failed

    def renew_leases(self, instance: str, seconds: float) -> int:
        """Extend the claims of the jobs ``instance``'s workers run by ``seconds`` from now;
        the number of jobs. The instance's supervisor calls it well within ``seconds``."""
        return self._db.run(
            "UPDATE jobs SET lease_until = ? WHERE instance = ? AND state = ?",
            (time.time() + seconds, instance, JobState.running.value),
        )

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
        with self._db.transaction() as db:
            changed = db.run(query, args)
            if changed:
                _ended(db, JobState.failed, job_id, self._sinks)
        return changed > 0

    def requeue_dead(self, job_id: str, worker_pid: int, max_attempts: int) -> JobState | None:
        """A running job whose worker died with the fork server (the OOM killer's usual victim
        besides the workers): queued again, and the start counted as a death, as
        :meth:`requeue_orphans` counts a service's; failed once it has died ``max_attempts``
        times. Returns the job's new state, ``None`` if ``worker_pid`` no longer runs it."""
        with self._db.transaction() as db:
            row = db.one(
                "SELECT attempts - stops AS deaths FROM jobs WHERE id = ? AND state = ?"
                f" AND worker_pid = ?{self._db.lock_rows}",
                (job_id, JobState.running.value, worker_pid),
            )
            if row is None:
                return None
            if row["deaths"] >= max_attempts:
                what = "the service's fork server died"
                _fail(
                    db, job_id, f"{what} while this job ran, {_times(row['deaths'])}", self._sinks
                )
                return JobState.failed
            _queue_again(db, job_id)
        self._db.notify_queued()
        return JobState.queued

    def requeue_running(self, job_id: str, worker_pid: int) -> bool:
        """Put a job back in the queue (its worker was stopped by a clean shutdown); the start
        does not count against ``max_attempts``."""
        changed = self._db.run(
            "UPDATE jobs SET state = ?, worker_pid = NULL, instance = NULL, lease_until = NULL,"
            " frames_done = 0, fps = NULL, stops = stops + 1"
            " WHERE id = ? AND state = ? AND worker_pid = ?",
            (JobState.queued.value, job_id, JobState.running.value, worker_pid),
        )
        if changed:
            self._db.notify_queued()
        return changed > 0

    # -- a worker's writes ---------------------------------------------------------------------

    def claim(
        self, worker_pid: int, instance: str | None = None, lease: float | None = None
    ) -> JobRecord | None:
        """Take the oldest queued job: it becomes running, attempted once more, owned by
        ``worker_pid`` of ``instance``, whose claim holds for ``lease`` seconds unless renewed
        (:meth:`renew_leases`). Claimers of a shared database skip the rows others are taking
        (``FOR UPDATE SKIP LOCKED``) rather than wait for them."""
        with self._db.transaction() as db:
            row = db.one(
                f"SELECT id FROM jobs WHERE state = ? ORDER BY created_at, {self._db.order}"
                f" LIMIT 1{self._db.skip_locked}",
                (JobState.queued.value,),
            )
            if row is None:
                return None
            now = time.time()
            db.run(
                "UPDATE jobs SET state = ?, started_at = ?, progressed_at = ?,"
                " attempts = attempts + 1, worker_pid = ?, frames_done = 0, fps = NULL,"
                " instance = ?, lease_until = ? WHERE id = ?",
                (
                    JobState.running.value,
                    now,
                    now,
                    worker_pid,
                    instance,
                    None if lease is None else now + lease,
                    row["id"],
                ),
            )
        return self.get(row["id"])

    def report_progress(
        self, job: JobRecord, worker_pid: int, frames_done: int, fps: float | None, new_frames: int
    ) -> bool:
        """Record progress; ``False`` when the job is no longer this attempt's or is to stop
        (cancelled, failed from outside, requeued). A report with more frames read than the
        last one moves ``progressed_at`` (the supervisor's stall limit reads it)."""
        with self._db.transaction() as db:
            changed = db.run(
                "UPDATE jobs SET progressed_at = CASE WHEN frames_done = ? THEN progressed_at"
                " ELSE ? END, frames_done = ?, fps = ? WHERE id = ? AND attempts = ?"
                " AND worker_pid = ? AND state = ? AND cancel_requested = 0",
                (frames_done, time.time(), frames_done, fps, job.id, job.attempts, worker_pid,
                 JobState.running.value),
            )  # fmt: skip
            if changed and new_frames:
                _add_counter(db, "frames_processed", new_frames)
        return changed > 0

    def cancel_requested(self, job_id: str) -> bool:
        row = self._db.one("SELECT cancel_requested FROM jobs WHERE id = ?", (job_id,))
        return row is None or bool(row["cancel_requested"])

    def finish(
        self,
        job: JobRecord,
        worker_pid: int,
        state: JobState,
        *,
        error: str | None = None,
        results: dict[str, str] | None = None,
        warnings: builtins.list[str] | None = None,
        frames_total: int | None = None,
        analytics: AnalyticsCounts | None = None,
    ) -> bool:
        """End the worker's attempt; ``False`` when the job was no longer its own. The job's
        summary (with the ``analytics`` counts of its zones and lines) goes to the sinks."""
        with self._db.transaction() as db:
            changed = db.run(
                "UPDATE jobs SET state = ?, finished_at = ?, error = ?, results = ?, warnings = ?,"
                " frames_total = COALESCE(?, frames_total), lease_until = NULL"
                " WHERE id = ? AND attempts = ? AND worker_pid = ? AND state = ?",
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
            if changed:
                _ended(db, state, job.id, self._sinks, analytics)
        return changed > 0


# -- statements inside a transaction --------------------------------------------------------------


def _queue_again(db: Statements, job_id: str) -> None:
    db.run(
        "UPDATE jobs SET state = ?, worker_pid = NULL, instance = NULL, lease_until = NULL,"
        " frames_done = 0, fps = NULL WHERE id = ?",
        (JobState.queued.value, job_id),
    )


def _fail(db: Statements, job_id: str, what: str, sinks: Sequence[str]) -> None:
    """Fail a job that died under its start too often; it is not started again."""
    db.run(
        "UPDATE jobs SET state = ?, finished_at = ?, error = ?, worker_pid = NULL,"
        " lease_until = NULL WHERE id = ?",
        (JobState.failed.value, time.time(), f"{what}; it is not started again", job_id),
    )
    _ended(db, JobState.failed, job_id, sinks)


def _ended(
    db: Statements,
    state: JobState,
    job_id: str,
    sinks: Sequence[str],
    analytics: AnalyticsCounts | None = None,
) -> None:
    """What follows a job's end, in its transaction: the metrics' counters, and its summary
    queued for ``sinks`` (:func:`~service.delivery.messages.job_summary`): a job that ended
    is announced once, and one that did not end is not."""
    row = db.one(
        "SELECT started_at, finished_at, options, video_filename, results, error, warnings,"
        " frames_done FROM jobs WHERE id = ?",
        (job_id,),
    )
    if row is not None and sinks:
        summary = job_summary(
            job_id,
            state,
            filename=row["video_filename"],
            labels=json.loads(row["options"]).get("labels") or {},
            results=json.loads(row["results"]),
            frames=row["frames_done"],
            error=row["error"],
            warnings=json.loads(row["warnings"]),
            analytics=analytics,
        )
        queue_events(db, sinks, [summary])
    _add_counter(db, f"jobs_{state.value}", 1)
    if row and row["started_at"] and row["finished_at"]:
        seconds = row["finished_at"] - row["started_at"]
        _add_counter(db, "processing_seconds", seconds)
        _add_counter(db, "processing_count", 1)
        for bound in DURATION_BUCKETS:
            if seconds <= bound:
                _add_counter(db, f"processing_le_{bound:g}", 1)


def _add_counter(db: Statements, name: str, delta: float) -> None:
    db.run(
        "INSERT INTO counters (name, value) VALUES (?, ?)"
        " ON CONFLICT (name) DO UPDATE SET value = counters.value + excluded.value",
        (name, delta),
    )


def _times(count: int) -> str:
    """``once``, ``twice``, ``3 times``."""
    return {1: "once", 2: "twice"}.get(count, f"{count} times")
