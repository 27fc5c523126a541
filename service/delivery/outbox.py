"""The outbox: events waiting for their sinks, kept in the job database so that an event
survives a restart of the service and reaches a receiver that was down when it happened.

A producer (a stream's worker process, a finished job) adds each event once per sink, under
an idempotency key; adding it again is a no-op. A dispatcher (:mod:`service.delivery.dispatch`)
claims the due events of its sink in order, for a lease, sends them and marks them delivered,
or puts the failed one back for later. Instances that share a PostgreSQL database share the
outbox: a claim skips the rows another instance holds.

Counts for ``/metrics`` (events produced, delivered, retried, dropped, per sink) are kept in
the database's ``counters`` table, so they add up across processes and instances.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from service.jobs.database import Database, Statements, open_database

__all__ = ["OUTBOX_SCHEMA", "Outbox", "OutboxEvent", "OutgoingEvent", "queue_events"]

OUTBOX_SCHEMA = """
CREATE TABLE IF NOT EXISTS event_outbox (
    id INTEGER PRIMARY KEY,
    sink TEXT NOT NULL,
    key TEXT NOT NULL,
    topic TEXT NOT NULL,
    body TEXT NOT NULL,
    created_at REAL NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    due_at REAL NOT NULL,
    claimed_until REAL,
    delivered_at REAL,
    last_error TEXT,
    UNIQUE (sink, key)
);
CREATE INDEX IF NOT EXISTS event_outbox_due ON event_outbox (sink, delivered_at, id);
CREATE TABLE IF NOT EXISTS counters (name TEXT PRIMARY KEY, value REAL NOT NULL);
"""
"""SQLite's tables (PostgreSQL's are version 2 of its schema, :mod:`service.jobs.database`)."""

COUNTS = ("produced", "delivered", "retried", "dropped")
"""The counts kept per sink, as ``events_<count>:<sink>`` in ``counters``."""


@dataclass(frozen=True, slots=True)
class OutgoingEvent:
    """An event for a sink: its idempotency ``key`` (the same event gets the same key), a
    ``topic`` (the MQTT topic, or the event type for a webhook) and its JSON ``body``."""

    key: str
    topic: str
    body: str


@dataclass(frozen=True, slots=True)
class OutboxEvent:
    """An event claimed from the outbox."""

    id: int
    key: str
    topic: str
    body: str
    attempts: int
    created_at: float


class Outbox:
    """The outbox in the job database (a SQLite file, or ``postgresql://...``)."""

    def __init__(self, where: str | Path | Database, timeout: float = 30.0) -> None:
        self._db = open_database(where, timeout) if isinstance(where, str | Path) else where
        self._db.migrate(OUTBOX_SCHEMA)  # PostgreSQL: its schema has the table

    def close(self) -> None:
        self._db.close()

    def add(self, sinks: Iterable[str], events: Iterable[OutgoingEvent]) -> int:
        """Queue ``events`` for every one of ``sinks``, in one transaction
        (:func:`queue_events`). Returns how many were queued."""
        with self._db.transaction() as tx:
            return queue_events(tx, sinks, events)

    def claim(self, sink: str, limit: int, lease: float) -> list[OutboxEvent]:
        """The oldest due events of ``sink`` (up to ``limit``), held for ``lease`` seconds:
        until then no other dispatcher claims them."""
        now = time.time()
        with self._db.transaction() as tx:
            rows = tx.all(
                "SELECT id, key, topic, body, attempts, created_at FROM event_outbox"
                " WHERE sink = ? AND delivered_at IS NULL AND due_at <= ?"
                " AND (claimed_until IS NULL OR claimed_until < ?)"
                f" ORDER BY id LIMIT ?{self._db.skip_locked}",
                (sink, now, now, limit),
            )
            for row in rows:
                tx.run(
                    "UPDATE event_outbox SET claimed_until = ? WHERE id = ?",
                    (now + lease, row["id"]),
                )
        return [OutboxEvent(**row) for row in rows]

    def delivered(self, sink: str, event: OutboxEvent) -> None:
        with self._db.transaction() as tx:
            tx.run(
                "UPDATE event_outbox SET delivered_at = ?, claimed_until = NULL WHERE id = ?",
                (time.time(), event.id),
            )
            _count(tx, "delivered", sink, 1)

    def failed(self, sink: str, event: OutboxEvent, error: str, retry_in: float) -> None:
        """``event`` could not be sent; it is due again in ``retry_in`` seconds."""
        with self._db.transaction() as tx:
            tx.run(
                "UPDATE event_outbox SET attempts = attempts + 1, last_error = ?,"
                " due_at = ?, claimed_until = NULL WHERE id = ?",
                (error[:500], time.time() + retry_in, event.id),
            )
            _count(tx, "retried", sink, 1)

    def release(self, events: Iterable[OutboxEvent]) -> None:
        """Give back claimed events not tried (a dispatcher stopping, a sink backing off)."""
        for event in events:
            self._db.run("UPDATE event_outbox SET claimed_until = NULL WHERE id = ?", (event.id,))

    def expire(self, max_age: float, keep_delivered: float) -> dict[str, int]:
        """Drop undelivered events older than ``max_age`` seconds (counted as dropped, per
        sink) and forget delivered ones after ``keep_delivered`` seconds."""
        now = time.time()
        with self._db.transaction() as tx:
            old = tx.all(
                "SELECT sink, count(*) AS n FROM event_outbox WHERE delivered_at IS NULL"
                " AND created_at < ? GROUP BY sink",
                (now - max_age,),
            )
            tx.run(
                "DELETE FROM event_outbox WHERE (delivered_at IS NULL AND created_at < ?)"
                " OR delivered_at < ?",
                (now - max_age, now - keep_delivered),
            )
            for row in old:
                _count(tx, "dropped", row["sink"], row["n"])
        return {row["sink"]: int(row["n"]) for row in old}

    def pending(self) -> dict[str, int]:
        """Undelivered events per sink."""
        rows = self._db.all(
            "SELECT sink, count(*) AS n FROM event_outbox WHERE delivered_at IS NULL GROUP BY sink"
        )
        return {row["sink"]: int(row["n"]) for row in rows}

    def counts(self) -> dict[str, dict[str, int]]:
        """``{sink: {"produced": n, "delivered": n, "retried": n, "dropped": n}}``."""
        rows = self._db.all("SELECT name, value FROM counters WHERE substr(name, 1, 7) = 'events_'")
        counts: dict[str, dict[str, int]] = {}
        for row in rows:
            kind, _, sink = row["name"].removeprefix("events_").partition(":")
            if kind in COUNTS and sink:
                counts.setdefault(sink, dict.fromkeys(COUNTS, 0))[kind] = int(row["value"])
        return counts


def queue_events(tx: Statements, sinks: Iterable[str], events: Iterable[OutgoingEvent]) -> int:
    """Queue ``events`` for every one of ``sinks`` inside the caller's transaction ``tx`` (a
    job's end and its summary are recorded together, or neither is); an event already queued
    for a sink (its key) is not queued again. Returns how many were queued."""
    now = time.time()
    events = tuple(events)
    queued = 0
    for sink in sinks:
        added = sum(
            tx.run(
                "INSERT INTO event_outbox (sink, key, topic, body, created_at, due_at)"
                " VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (sink, key) DO NOTHING",
                (sink, event.key, event.topic, event.body, now, now),
            )
            for event in events
        )
        _count(tx, "produced", sink, added)
        queued += added
    return queued


def _count(tx: Statements, kind: str, sink: str, n: int) -> None:
    if n:
        tx.run(
            "INSERT INTO counters (name, value) VALUES (?, ?)"
            " ON CONFLICT (name) DO UPDATE SET value = counters.value + excluded.value",
            (f"events_{kind}:{sink}", n),
        )
