"""The streams table: which streams exist, so that they start again with the service.

It lives in the job database (its own tables and connection): the data folder's SQLite file,
or the PostgreSQL database that instances of the service share (:mod:`service.jobs.database`).
A stream stopped with ``DELETE`` keeps its row (``stopped_at`` set) until it is deleted a
second time.

Beside it, ``stream_track_ids`` holds per camera the highest track id a worker may have
published (ids are reserved in blocks, see :mod:`service.streams.track_ids`): a worker that starts
(the service restarted, or the worker died) continues above it, so an id is never reused within
a stream. Its row outlives the stream's: a camera tracked again after a ``DELETE`` gets new ids
too, so a consumer that keeps tracks by camera and id never sees one id name two people.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from api_schemas.streams import StreamSpec
from service.jobs.database import open_database

_SCHEMA = """
CREATE TABLE IF NOT EXISTS streams (
    id TEXT PRIMARY KEY,
    spec TEXT NOT NULL,
    created_at REAL NOT NULL,
    stopped_at REAL
);
CREATE TABLE IF NOT EXISTS stream_track_ids (
    camera TEXT PRIMARY KEY,
    reserved INTEGER NOT NULL
);
"""


@dataclass(frozen=True, slots=True)
class StreamRecord:
    id: str
    spec: StreamSpec
    created_at: float
    stopped_at: float | None


class StreamStore:
    """Stream specifications in the job database; safe to use from several threads."""

    def __init__(self, where: str | Path, timeout: float = 30.0) -> None:
        self.path = where
        self._db = open_database(where, timeout)
        self._db.migrate(_SCHEMA)  # PostgreSQL: its schema has these tables

    def close(self) -> None:
        self._db.close()

    def put(self, spec: StreamSpec) -> StreamRecord:
        """Create the stream, or replace a stopped one of the same camera."""
        now = time.time()
        self._db.run(
            "INSERT INTO streams (id, spec, created_at) VALUES (?, ?, ?) "
            "ON CONFLICT(id) DO UPDATE SET spec = excluded.spec, "
            "created_at = excluded.created_at, stopped_at = NULL",
            (spec.camera, spec.model_dump_json(), now),
        )
        return StreamRecord(spec.camera, spec, now, None)

    def mark_stopped(self, stream_id: str) -> float:
        now = time.time()
        self._db.run("UPDATE streams SET stopped_at = ? WHERE id = ?", (now, stream_id))
        return now

    def delete(self, stream_id: str) -> None:
        self._db.run("DELETE FROM streams WHERE id = ?", (stream_id,))

    def all(self) -> list[StreamRecord]:
        return [
            StreamRecord(
                row["id"],
                StreamSpec.from_stored(row["spec"]),
                row["created_at"],
                row["stopped_at"],
            )
            for row in self._db.all("SELECT * FROM streams ORDER BY created_at")
        ]

    def reserved_track_ids(self, camera: str) -> int:
        """The highest track id the camera's workers may have published (0: none yet)."""
        row = self._db.one("SELECT reserved FROM stream_track_ids WHERE camera = ?", (camera,))
        return int(row["reserved"]) if row is not None else 0

    def reserve_track_ids(self, camera: str, up_to: int) -> None:
        """Record that ids up to ``up_to`` may be published; never lowers the record.

        Raises
        ------
        sqlite3.Error, psycopg.Error
            The database cannot be written (a full disk, locked for longer than the timeout, a
            server away): :data:`service.jobs.database.DATABASE_ERRORS`.
        """
        greatest = self._db.greatest("stream_track_ids.reserved", "excluded.reserved")
        self._db.run(
            "INSERT INTO stream_track_ids (camera, reserved) VALUES (?, ?) "
            f"ON CONFLICT(camera) DO UPDATE SET reserved = {greatest}",
            (camera, up_to),
        )
