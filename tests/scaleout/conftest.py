"""Fixtures for the scale-out tests (issue 79): real PostgreSQL servers of the tests' own.

Each pytest-xdist worker starts its own servers (a session fixture lives in one worker), on
free loopback ports in folders of :func:`tempfile.mkdtemp`: as root the server runs as
``nobody``, who cannot reach pytest's ``tmp_path`` (see :mod:`tests.postgres`).
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import psycopg
import pytest

from tests.postgres import PostgresServer, running_postgres
from tests.service.conftest import long_video, pets_cut, pets_short  # noqa: F401 (videos)


def _server() -> Iterator[PostgresServer]:
    with running_postgres() as server:
        yield server


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    """A running server shared by the worker's tests, with the database ``vtrack``
    (:attr:`PostgresServer.url`). Tests give the tables and databases they create names of
    their own. A test may kill or stop it: the next test finds it running again, on the same
    port with the same data (:func:`_postgres_running_again`)."""
    yield from _server()


@pytest.fixture(autouse=True)
def _postgres_running_again(request: pytest.FixtureRequest) -> Iterator[None]:
    """After a test of the shared server that left it dead (it failed between
    :meth:`~PostgresServer.kill` and :meth:`~PostgresServer.restart`, say), restart it, so
    that the tests after it do not fail too."""
    if "postgres" not in request.fixturenames:
        yield
        return
    server: PostgresServer = request.getfixturevalue("postgres")
    yield
    if not server.running:
        server.restart()


@pytest.fixture
def fresh_postgres() -> Iterator[PostgresServer]:
    """A running server of the test's own (about 0.5 s to create), gone after the test."""
    yield from _server()


@pytest.fixture
def database_url(postgres) -> str:
    """A new, empty database on the tests' server: tests do not see each other's jobs."""
    name = f"jobs_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgres.url, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    return postgres.url.rsplit("/", 1)[0] + f"/{name}"
