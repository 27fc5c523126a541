"""The tests' own PostgreSQL server (tests/postgres.py), and the features of PostgreSQL the
distributed job store relies on: row locks that other workers skip, notifications between
sessions, committed data that outlives a crash of the server."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator

import psycopg
import pytest

from tests.postgres import DATABASE, PostgresServer

pytestmark = pytest.mark.scaleout


@pytest.fixture
def table(postgres: PostgresServer) -> Iterator[str]:
    """A table of the test's own in the shared server, ``(id int primary key)``, rows 1-3."""
    name = f"jobs_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres.url, autocommit=True) as connection:
        connection.execute(f"CREATE TABLE {name} (id int PRIMARY KEY)")
        connection.execute(f"INSERT INTO {name} SELECT generate_series(1, 3)")
    yield name
    with psycopg.connect(postgres.url, autocommit=True) as connection:
        connection.execute(f"DROP TABLE {name}")


def test_server_answers_on_its_url(postgres: PostgresServer) -> None:
    assert postgres.url == f"postgresql://postgres@127.0.0.1:{postgres.port}/{DATABASE}"
    with psycopg.connect(postgres.url) as connection:
        row = connection.execute("SELECT current_database(), current_user, 6 * 7").fetchone()
        assert row == (DATABASE, "postgres", 42)
        assert connection.execute("SHOW fsync").fetchone() == ("off",)
    if os.geteuid() == 0:  # PostgreSQL refuses root: the server runs as nobody
        assert postgres.data.stat().st_uid != 0


def test_skip_locked_hands_each_row_to_one_session(postgres: PostgresServer, table: str) -> None:
    claim_all = f"SELECT id FROM {table} ORDER BY id FOR UPDATE SKIP LOCKED"
    claim_one = claim_all.replace("FOR UPDATE", "LIMIT 1 FOR UPDATE")
    with psycopg.connect(postgres.url) as first, psycopg.connect(postgres.url) as second:
        # a session that waited for the lock instead of skipping the row would fail, not hang
        second.execute("SET lock_timeout = '5s'")
        second.commit()
        assert first.execute(claim_one).fetchone() == (1,)
        assert second.execute(claim_one).fetchone() == (2,)  # row 1 is first's: skipped
        assert second.execute(claim_all).fetchall() == [(2,), (3,)]
        first.commit()  # row 1 free again
        assert second.execute(claim_all).fetchall() == [(1,), (2,), (3,)]
        second.commit()


def test_listen_notify_crosses_sessions(postgres: PostgresServer) -> None:
    channel = f"jobs_{uuid.uuid4().hex[:12]}"
    with (
        psycopg.connect(postgres.url, autocommit=True) as listener,
        psycopg.connect(postgres.url, autocommit=True) as notifier,
    ):
        listener.execute(f"LISTEN {channel}")
        notifier.execute("SELECT pg_notify(%s, %s)", (channel, "job 17"))
        notes = list(listener.notifies(timeout=10, stop_after=1))
        sender = notifier.info.backend_pid
    assert [(note.channel, note.payload, note.pid) for note in notes] == [
        (channel, "job 17", sender)
    ]


def test_committed_data_survives_a_killed_server(fresh_postgres: PostgresServer) -> None:
    server = fresh_postgres
    url = server.url
    with psycopg.connect(url, autocommit=True) as setup:
        setup.execute("CREATE TABLE jobs (id int PRIMARY KEY, state text)")
    connection = psycopg.connect(url, autocommit=True)
    try:
        connection.execute("INSERT INTO jobs VALUES (1, 'done')")
        server.kill()
        assert not server.running
        with pytest.raises(psycopg.OperationalError):
            connection.execute("SELECT 1")
    finally:
        connection.close()
    with pytest.raises(psycopg.OperationalError):
        psycopg.connect(url, connect_timeout=5)

    server.restart()
    assert server.url == url  # same port, same data
    with psycopg.connect(url) as connection:
        assert connection.execute("SELECT id, state FROM jobs").fetchall() == [(1, "done")]
