"""The streams table: which streams exist, so that they start again with the service.

It lives in the job database file (its own table and connection). A stream stopped with
``DELETE`` keeps its row (``stopped_at`` set) until it is deleted a second time.

Beside it, ``stream_track_ids`` holds per camera the highest track id a worker may have
published (ids are reserved in blocks, see :mod:`service.streams.worker`): a worker that starts
(the service restarted, or the worker died) continues above it, so an id is never reused within
a stream. Its row outlives the stream's: a camera tracked again after a ``DELETE`` gets new ids
too, so a consumer that keeps tracks by camera and id never sees one id name two people.
"""

from __future__ import annotations

import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from api_schemas.streams import StreamSpec

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
    """Stream specifications in SQLite; safe to use from several threads."""

    def __init__(self, path: Path, timeout: float = 30.0) -> None:
        self.path = path
        self._db = sqlite3.connect(path, check_same_thread=False, timeout=timeout)
        self._db.row_factory = sqlite3.Row
        self._lock = threading.Lock()
        with self._lock, self._db:
            self._db.executescript(_SCHEMA)

    def close(self) -> None:
        self._db.close()

    def put(self, spec: StreamSpec) -> StreamRecord:
        """Create the stream, or replace a stopped one of the same camera."""
        now = time.time()
        with self._lock, self._db:
            self._db.execute(
                "INSERT INTO streams (id, spec, created_at) VALUES (?, ?, ?) "
                "ON CONFLICT(id) DO UPDATE SET spec = excluded.spec, "
                "created_at = excluded.created_at, stopped_at = NULL",
                (spec.camera, spec.model_dump_json(), now),
            )
        return StreamRecord(spec.camera, spec, now, None)

    def mark_stopped(self, stream_id: str) -> float:
        now = time.time()
        with self._lock, self._db:
            self._db.execute("UPDATE streams SET stopped_at = ? WHERE id = ?", (now, stream_id))
        return now

    def delete(self, stream_id: str) -> None:
        with self._lock, self._db:
            self._db.execute("DELETE FROM streams WHERE id = ?", (stream_id,))

    def all(self) -> list[StreamRecord]:
        with self._lock:
            rows = self._db.execute("SELECT * FROM streams ORDER BY created_at").fetchall()
        return [
            StreamRecord(
                row["id"],
                StreamSpec.from_stored(row["spec"]),
                row["created_at"],
                row["stopped_at"],
            )
            for row in rows
        ]

    def reserved_track_ids(self, camera: str) -> int:
        """The highest track id the camera's workers may have published (0: none yet)."""
        with self._lock:
            row = self._db.execute(
                "SELECT reserved FROM stream_track_ids WHERE camera = ?", (camera,)
            ).fetchone()
        return int(row["reserved"]) if row is not None else 0

    def reserve_track_ids(self, camera: str, up_to: int) -> None:
        """Record that ids up to ``up_to`` may be published; never lowers the record.

        Raises
        ------
        sqlite3.Error
            The database cannot be written (a full disk, locked for longer than the timeout).
        """
        with self._lock, self._db:
            self._db.execute(
                "INSERT INTO stream_track_ids (camera, reserved) VALUES (?, ?) "
                "ON CONFLICT(camera) DO UPDATE SET reserved = max(reserved, excluded.reserved)",
                (camera, up_to),
            )
