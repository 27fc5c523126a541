"""The job store's SQL connection: one SQLite file (the embedded default) or a PostgreSQL
server (``VTRACK_DATABASE_URL``, many service instances on one queue, issue 79).

The store's statements are written once, with ``?`` placeholders, and run on either; what
differs is said here: how a write transaction takes its lock, the column that orders rows of
equal creation time (SQLite's ``rowid``, PostgreSQL's ``seq``), row locks that other claimers
skip, schema changes, and how an idle worker waits for work (polling the file; ``LISTEN`` on
the server). Rows come back as dicts, fetched before the connection is given back.
"""

from __future__ import annotations

import sqlite3
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any, Protocol

import psycopg

Row = dict[str, Any]

DATABASE_ERRORS: tuple[type[Exception], ...] = (sqlite3.Error, psycopg.Error)
"""What a statement raises when the database cannot serve it (a full disk, a lock held too
long, a server away): callers that go on without the database catch these."""

JOBS_CHANNEL = "vtrack_jobs"
"""PostgreSQL's notification channel: a job was queued (new, or again)."""


class Statements(Protocol):
    """What the store runs statements on: the database, or one of its transactions."""

    def one(self, sql: str, args: Sequence[Any] = ()) -> Row | None: ...

    def all(self, sql: str, args: Sequence[Any] = ()) -> list[Row]: ...

    def run(self, sql: str, args: Sequence[Any] = ()) -> int:
        """Run a write; the number of rows it changed."""
        ...


class Database(Statements, Protocol):
    """A job database (:class:`SqliteDatabase` or :class:`PostgresDatabase`)."""

    order: str
    """The column that orders jobs created in the same instant: the order of insertion."""
    skip_locked: str
    """What :meth:`JobStore.claim`'s select ends with so that claimers skip each other's rows."""
    lock_rows: str
    """What a select ends with that locks its rows until the transaction ends."""

    def transaction(self) -> Any:
        """A context manager: a write transaction, as :class:`Statements`."""
        ...

    def rounded(self, column: str, digits: int) -> str:
        """SQL of ``column`` rounded to ``digits`` decimals."""
        ...

    def greatest(self, first: str, second: str) -> str:
        """SQL of the larger of two values."""
        ...

    def migrate(self, schema: str, added_columns: dict[str, str] | None = None) -> None:
        """Create the tables (SQLite: ``schema``), and add ``jobs``' columns newer than a
        database made before."""
        ...

    def notify_queued(self) -> None:
        """Wake the idle workers of every instance: a job was queued."""
        ...

    def wait_for_work(self, timeout: float) -> None:
        """Return after ``timeout`` seconds, or sooner when a job was queued."""
        ...

    def checkpoint(self) -> None:
        """Leave no copy of deleted rows in logs the database keeps (best effort)."""
        ...

    def close(self) -> None: ...


class SqliteDatabase:
    """A SQLite file in WAL mode, shared by the threads of one process; every process (the API,
    each worker) opens its own."""

    order = "rowid"
    skip_locked = lock_rows = ""  # BEGIN IMMEDIATE already takes the whole file

    def __init__(self, path: Path, timeout: float = 30.0) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()
        self._db = sqlite3.connect(
            path, timeout=timeout, isolation_level=None, check_same_thread=False
        )
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        self._db.execute(f"PRAGMA busy_timeout={int(timeout * 1000)}")
        self._db.execute("PRAGMA secure_delete=ON")  # see JobStore.delete()

    def one(self, sql: str, args: Sequence[Any] = ()) -> Row | None:
        with self._lock:
            row = self._db.execute(sql, args).fetchone()
        return dict(row) if row is not None else None

    def all(self, sql: str, args: Sequence[Any] = ()) -> list[Row]:
        with self._lock:
            return [dict(row) for row in self._db.execute(sql, args).fetchall()]

    def run(self, sql: str, args: Sequence[Any] = ()) -> int:
        with self._lock:
            return self._db.execute(sql, args).rowcount

    @contextmanager
    def transaction(self) -> Iterator[SqliteDatabase]:
        """Takes the database lock at once (``BEGIN IMMEDIATE``: no upgrade deadlocks)."""
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    def rounded(self, column: str, digits: int) -> str:
        return f"round({column}, {digits})"

    def greatest(self, first: str, second: str) -> str:
        return f"max({first}, {second})"

    def migrate(self, schema: str, added_columns: dict[str, str] | None = None) -> None:
        with self._lock:
            self._db.executescript(schema)
            if not added_columns:
                return
            have = {row["name"] for row in self._db.execute("PRAGMA table_info(jobs)")}
            for name, definition in added_columns.items():
                if name not in have:
                    with suppress(sqlite3.OperationalError):  # another process's race
                        self._db.execute(f"ALTER TABLE jobs ADD COLUMN {name} {definition}")

    def notify_queued(self) -> None:
        pass  # the workers of the one instance poll the file

    def wait_for_work(self, timeout: float) -> None:
        time.sleep(timeout)

    def checkpoint(self) -> None:
        # as far as no reader still needs the log: a worker's open read is rare and short,
        # and the next deletion empties what it kept
        with self._lock:
            self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()

    def close(self) -> None:
        """The write-ahead log moved into the database file first, so that after a clean stop
        ``jobs.sqlite3`` alone holds every job (a copy or backup of it misses nothing)."""
        with self._lock:
            with suppress(sqlite3.Error):
                self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
            self._db.close()


_POSTGRES_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    seq BIGINT GENERATED ALWAYS AS IDENTITY,
    id TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    options TEXT NOT NULL,
    video_filename TEXT,
    video_path TEXT NOT NULL,
    result_dir TEXT NOT NULL,
    created_at DOUBLE PRECISION NOT NULL,
    started_at DOUBLE PRECISION,
    finished_at DOUBLE PRECISION,
    frames_done INTEGER NOT NULL DEFAULT 0,
    frames_total INTEGER,
    fps DOUBLE PRECISION,
    error TEXT,
    warnings TEXT NOT NULL DEFAULT '[]',
    results TEXT NOT NULL DEFAULT '{}',
    attempts INTEGER NOT NULL DEFAULT 0,
    stops INTEGER NOT NULL DEFAULT 0,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    worker_pid INTEGER,
    progressed_at DOUBLE PRECISION,
    instance TEXT,
    lease_until DOUBLE PRECISION
);
CREATE INDEX IF NOT EXISTS jobs_by_state ON jobs (state, created_at, seq);
CREATE TABLE IF NOT EXISTS counters (name TEXT PRIMARY KEY, value DOUBLE PRECISION NOT NULL);
CREATE TABLE IF NOT EXISTS streams (
    id TEXT PRIMARY KEY,
    spec TEXT NOT NULL,
    created_at DOUBLE PRECISION NOT NULL,
    stopped_at DOUBLE PRECISION
);
CREATE TABLE IF NOT EXISTS stream_track_ids (camera TEXT PRIMARY KEY, reserved BIGINT NOT NULL);
"""
"""Version 1 of the PostgreSQL schema; later versions go in :data:`_POSTGRES_MIGRATIONS`."""

_POSTGRES_OUTBOX = """
CREATE TABLE IF NOT EXISTS event_outbox (
    id BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
    sink TEXT NOT NULL,
    key TEXT NOT NULL,
    topic TEXT NOT NULL,
    body TEXT NOT NULL,
    created_at DOUBLE PRECISION NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    due_at DOUBLE PRECISION NOT NULL,
    claimed_until DOUBLE PRECISION,
    delivered_at DOUBLE PRECISION,
    last_error TEXT,
    UNIQUE (sink, key)
);
CREATE INDEX IF NOT EXISTS event_outbox_due ON event_outbox (sink, delivered_at, id);
"""
"""Version 2: the events waiting for their sinks (:mod:`service.delivery.outbox`)."""

_POSTGRES_MIGRATIONS: tuple[str, ...] = (_POSTGRES_SCHEMA, _POSTGRES_OUTBOX)
"""The schema's versions in order: each runs once per database, in one transaction with the
version's row (``schema_version``), under an advisory lock so that instances starting together
do not run one twice. A new version is a new entry; an entry is never edited once released."""

_MIGRATION_LOCK = 7_447_079
"""The advisory lock's key (any constant of ours)."""


class PostgresDatabase:
    """A PostgreSQL database through a connection pool (psycopg 3), shared by the threads of
    one process; every process opens its own pool, after it forked."""

    order = "seq"
    skip_locked = " FOR UPDATE SKIP LOCKED"
    lock_rows = " FOR UPDATE"

    def __init__(self, url: str, max_connections: int = 4) -> None:
        from psycopg.rows import DictRow, dict_row
        from psycopg_pool import ConnectionPool

        self.url = url
        # one connection first: a server that is not there, or refuses us, is said at once
        # in psycopg's words (the pool would retry in the background, logging each failure)
        psycopg.connect(url, connect_timeout=10).close()
        self._pool = ConnectionPool(
            url,
            min_size=1,
            max_size=max_connections,
            # the class typed by its rows (psycopg's way), which the row factory makes dicts
            connection_class=psycopg.Connection[DictRow],
            kwargs={"autocommit": True, "row_factory": dict_row},
            # a server restarted under the pool: connections checked before use, and replaced
            check=ConnectionPool.check_connection,
            # a server that is away: an error within seconds (PoolTimeout is psycopg's
            # OperationalError), not a request held for the default 30 s
            timeout=5.0,
            open=False,
        )
        self._pool.open(wait=True, timeout=30)
        self._listener: Any = None

    @staticmethod
    def _sql(sql: str) -> str:
        # psycopg's placeholders; the store's statements hold no literal "?" or "%"
        return sql.replace("?", "%s")

    def one(self, sql: str, args: Sequence[Any] = ()) -> Row | None:
        with self._pool.connection() as connection:
            return connection.execute(self._sql(sql), args).fetchone()

    def all(self, sql: str, args: Sequence[Any] = ()) -> list[Row]:
        with self._pool.connection() as connection:
            return connection.execute(self._sql(sql), args).fetchall()

    def run(self, sql: str, args: Sequence[Any] = ()) -> int:
        with self._pool.connection() as connection:
            return connection.execute(self._sql(sql), args).rowcount

    @contextmanager
    def transaction(self) -> Iterator[_PostgresTransaction]:
        with self._pool.connection() as connection, connection.transaction():
            yield _PostgresTransaction(connection)

    def rounded(self, column: str, digits: int) -> str:
        return f"round({column}::numeric, {digits})"

    def greatest(self, first: str, second: str) -> str:
        return f"greatest({first}, {second})"

    def migrate(self, schema: str, added_columns: dict[str, str] | None = None) -> None:
        """Bring the schema to its newest version (:data:`_POSTGRES_MIGRATIONS`); the SQLite
        schema and columns given are SQLite's and are not used here."""
        with self._pool.connection() as connection, connection.transaction():
            connection.execute("SELECT pg_advisory_xact_lock(%s)", (_MIGRATION_LOCK,))
            connection.execute("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER)")
            row = connection.execute("SELECT max(version) AS v FROM schema_version").fetchone()
            assert row is not None, "an aggregate gives one row"
            current = row["v"] or 0
            if current > len(_POSTGRES_MIGRATIONS):
                raise RuntimeError(
                    f"the job database's schema is version {current}, newer than this "
                    f"service's {len(_POSTGRES_MIGRATIONS)}: upgrade the service"
                )
            for version, migration in enumerate(_POSTGRES_MIGRATIONS, 1):
                if version > current:
                    connection.execute(migration)
                    connection.execute("INSERT INTO schema_version VALUES (%s)", (version,))

    def notify_queued(self) -> None:
        self.run(f"NOTIFY {JOBS_CHANNEL}")

    def wait_for_work(self, timeout: float) -> None:
        """``LISTEN`` on a connection of its own (a notification is delivered to the
        connections listening when it is sent; one sent between two waits is kept for the
        next); a broken connection is opened again at the next wait."""
        try:
            if self._listener is None or self._listener.closed:
                self._listener = psycopg.connect(self.url, autocommit=True)
                self._listener.execute(f"LISTEN {JOBS_CHANNEL}")
            for _ in self._listener.notifies(timeout=timeout, stop_after=1):
                break
        except psycopg.OperationalError:
            self._listener = None
            time.sleep(timeout)  # the server is away: the claim that follows says so

    def checkpoint(self) -> None:
        pass  # dead rows stay until the server's autovacuum reclaims them (docs/service.md)

    def close(self) -> None:
        if self._listener is not None:
            with suppress(psycopg.Error):
                self._listener.close()
        self._pool.close()


class _PostgresTransaction:
    """Statements on the one connection of a transaction."""

    def __init__(self, connection: Any) -> None:
        self._connection = connection

    def one(self, sql: str, args: Sequence[Any] = ()) -> Row | None:
        return self._connection.execute(PostgresDatabase._sql(sql), args).fetchone()

    def all(self, sql: str, args: Sequence[Any] = ()) -> list[Row]:
        return self._connection.execute(PostgresDatabase._sql(sql), args).fetchall()

    def run(self, sql: str, args: Sequence[Any] = ()) -> int:
        return self._connection.execute(PostgresDatabase._sql(sql), args).rowcount


def open_database(where: str | Path, timeout: float = 30.0) -> SqliteDatabase | PostgresDatabase:
    """``postgresql://...`` (or ``postgres://``) as :class:`PostgresDatabase`; anything else
    as the path of a SQLite file (whose lock is waited for ``timeout`` seconds)."""
    text = str(where)
    if text.startswith(("postgresql://", "postgres://")):
        return PostgresDatabase(text)
    return SqliteDatabase(Path(where), timeout)
