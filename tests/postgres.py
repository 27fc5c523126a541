"""A real PostgreSQL server of the tests' own: a throw-away cluster in a temporary folder,
on a free loopback port, for the distributed job store (issue 79).

Where the server's programs come from
-------------------------------------
From one source, the same on every machine: the PyPI wheel ``pgserver`` (the ``dev`` extra),
which bundles a relocatable PostgreSQL (16.2 in pgserver 0.1.4) in
``site-packages/pgserver/pginstall/{bin,lib,share}``. Only those programs are used (``initdb``
and ``postgres``); pgserver's Python API is never imported, since it picks its own data
folders, keeps servers running between processes and refuses to run as root. We chose the
wheel over a PostgreSQL installed on the machine (Debian's ``postgresql-15`` on a developer's
machine, maybe nothing on CI): with the system's server first and the wheel as a fallback,
CI and developers could test against different major versions without knowing it, and a test
that passes here could fail there. ``pip install -e '.[dev]'`` guarantees the wheel where
the project's tests run (pgserver has wheels for CPython 3.9-3.12 on Linux and macOS; see
pyproject.toml). :data:`BIN_ENV` names another ``bin`` folder explicitly, to try another
version (Debian's: ``/usr/lib/postgresql/15/bin``).

Root
----
PostgreSQL refuses to run as root, and the tests run as root in CI's containers. As root,
``initdb`` and ``postgres`` run as ``nobody`` (``subprocess.Popen(user=, group=,
extra_groups=[])``), which owns the cluster's ``data/`` and ``socket/`` folders; the folder
holding them must be reachable by that user (under ``/tmp/pytest-of-root``, mode 700, it is
not: :mod:`tests.scaleout.conftest` uses a folder of :func:`tempfile.mkdtemp`). Where that user
cannot reach the bundled programs (a virtualenv under ``/root``, mode 700), they are hard-linked
(or copied where links fail) into the folder, in the wheel's layout (``initdb`` finds libpq by
an RPATH relative to itself; both find ``share/`` and ``lib/`` relative to themselves). Not
root, they run as the current user.

Speed
-----
``fsync``, ``full_page_writes`` off: a test's data needs to survive the server's death
(:meth:`PostgresServer.kill`), not the machine's. ``synchronous_commit`` stays on: with
``fsync`` off a commit costs one ``write()`` to the page cache, not a flush to disk; off, a
commit acknowledged up to 0.6 s before :meth:`PostgresServer.kill` could be lost (it stays in
the server's WAL buffers), and a test of "a committed job survives the database's crash" would
fail now and then.
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import os
import pwd
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

import psycopg

from devtools.testing import free_port, wait_for

__all__ = [
    "BIN_ENV",
    "DATABASE",
    "SUPERUSER",
    "PostgresServer",
    "find_binaries",
    "running_postgres",
]

BIN_ENV = "VTRACK_POSTGRES_BIN"
"""Environment variable: a folder with ``initdb`` and ``postgres`` to use instead of pgserver's."""
DATABASE = "vtrack"
"""The database :meth:`PostgresServer.start` creates, which :attr:`PostgresServer.url` names."""
SUPERUSER = "postgres"
"""The cluster's superuser, who connects without a password over loopback TCP and the socket."""
UNPRIVILEGED_USER = "nobody"
"""Who runs the server when the tests run as root (uid and gid 65534 where no such user)."""

SETTINGS = {
    "listen_addresses": "127.0.0.1",
    "max_connections": "100",
    "shared_buffers": "32MB",
    "fsync": "off",
    "full_page_writes": "off",
    "synchronous_commit": "on",  # see the module's docstring
}
"""Server settings, passed as ``-c name=value`` (with the port and the socket's folder)."""

_PROGRAMS = ("initdb", "postgres")
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def find_binaries() -> Path:
    """The ``bin`` folder with ``initdb`` and ``postgres``: :data:`BIN_ENV`'s, else pgserver's.

    Raises
    ------
    FileNotFoundError
        Where neither names a folder with both programs, saying how to get them.
    """
    configured = os.environ.get(BIN_ENV)
    if configured:
        folder, source = Path(configured), f"{BIN_ENV}={configured}"
    else:
        spec = importlib.util.find_spec("pgserver")  # finds, does not import, the package
        if spec is None or not spec.submodule_search_locations:
            raise FileNotFoundError(
                "no PostgreSQL server programs for the tests: the dev extra's pgserver wheel "
                "bundles them (pip install -e '.[dev]'), or set "
                f"{BIN_ENV} to a folder with initdb and postgres "
                "(Debian's: /usr/lib/postgresql/15/bin)"
            )
        folder = Path(next(iter(spec.submodule_search_locations))) / "pginstall" / "bin"
        source = "the pgserver package"
    missing = [name for name in _PROGRAMS if not (folder / name).is_file()]
    if missing:
        raise FileNotFoundError(f"{folder} (from {source}) has no {' or '.join(missing)}")
    return folder


def _server_user() -> tuple[int, int] | None:
    """``(uid, gid)`` to run the server as, or ``None`` for the current user (not root)."""
    if os.geteuid() != 0:
        return None
    try:
        entry = pwd.getpwnam(UNPRIVILEGED_USER)
    except KeyError:
        return 65534, 65534
    return entry.pw_uid, entry.pw_gid


def _denied(path: Path, uid: int, gid: int, need: int = 1) -> Path | None:
    """The first folder on the way to ``path`` that user ``uid`` (group ``gid``, no others)
    may not search, or ``path`` itself where it lacks the ``need`` permission bits (4 read,
    2 write, 1 execute or search); ``None`` where nothing stands in the way. Mode bits only:
    no access control lists."""
    path = path.resolve()
    for part in [*reversed(path.parents), path]:
        want = need if part == path else 1
        status = part.stat()
        if status.st_uid == uid:
            bits = status.st_mode >> 6
        elif status.st_gid == gid:
            bits = status.st_mode >> 3
        else:
            bits = status.st_mode
        if bits & want != want:
            return part
    return None


def _link_or_copy(source: str | Path, target: str | Path) -> None:
    try:
        os.link(source, target)
    except OSError:  # another file system, or links refused
        shutil.copy2(source, target)


def _private_install(bin_folder: Path, target: Path) -> Path:
    """pgserver's programs and what they load, linked or copied below ``target`` in the
    wheel's layout (``pgserver/pginstall/{bin,lib/postgresql,share/postgresql}`` and
    ``pgserver.libs``); returns the new ``bin`` folder."""
    install = bin_folder.parent  # pginstall
    package = install.parent  # pgserver
    new_install = target / package.name / install.name
    (new_install / "bin").mkdir(parents=True)
    for name in _PROGRAMS:
        _link_or_copy(bin_folder / name, new_install / "bin" / name)
    for part in ("lib/postgresql", "share/postgresql"):
        if (install / part).is_dir():
            shutil.copytree(install / part, new_install / part, copy_function=_link_or_copy)
    libs = package.parent / f"{package.name}.libs"  # auditwheel's, initdb's RPATH
    if libs.is_dir():
        shutil.copytree(libs, target / libs.name, copy_function=_link_or_copy)
    for folder in [target, *target.rglob("*")]:
        if folder.is_dir():
            folder.chmod(0o755)
    return new_install / "bin"


_libc: Any = None


def _die_with_parent() -> None:
    """``preexec_fn``: the server quits at once (SIGQUIT, immediate shutdown) when the test
    process that started it dies, rather than outliving the run (Linux; the signal comes when
    the starting *thread* ends)."""
    if _libc is not None:
        _libc.prctl(_PR_SET_PDEATHSIG, signal.SIGQUIT)


class PostgresServer:
    """A PostgreSQL cluster in ``folder`` (``data/``, ``socket/``, ``postgres.log``), served on
    a free loopback port as :data:`SUPERUSER`, with trust authentication.

    Parameters
    ----------
    folder:
        An existing folder of the caller's (temporary); as root, one the unprivileged user can
        reach (see the module's docstring).

    Examples
    --------
    >>> with PostgresServer(folder) as server, psycopg.connect(server.url) as connection:
    ...     connection.execute("SELECT 1")
    """

    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder).absolute()
        self.data = self.folder / "data"
        self.socket_folder = self.folder / "socket"
        self.log_path = self.folder / "postgres.log"
        self.port: int | None = None
        self.process: subprocess.Popen[bytes] | None = None
        self._user = _server_user()
        self._bin: Path | None = None
        self._log_start = 0  # where the log of the latest start begins

    # --- addresses

    @property
    def url(self) -> str:
        """``postgresql://postgres@127.0.0.1:<port>/vtrack``: the database the tests use."""
        return self.database_url(DATABASE)

    def database_url(self, database: str) -> str:
        """The URL of another database of the cluster (``postgres``, say)."""
        if self.port is None:
            raise RuntimeError("the server has not been started: no port yet")
        return f"postgresql://{SUPERUSER}@127.0.0.1:{self.port}/{database}"

    @property
    def running(self) -> bool:
        """Whether the postmaster started here still runs."""
        return self.process is not None and self.process.poll() is None

    # --- life cycle

    def start(self, timeout: float = 30.0) -> PostgresServer:
        """Start the server, and wait until it accepts connections; the first time, create the
        cluster (``initdb``), pick a free port and create the database :data:`DATABASE`.

        Raises
        ------
        FileNotFoundError
            No server programs (:func:`find_binaries`).
        PermissionError
            As root: the folder is out of the unprivileged user's reach.
        RuntimeError
            ``initdb`` failed, or the server exited while starting (with the log's tail).
        TimeoutError
            The server did not get ready within ``timeout`` seconds (with the log's tail).
        """
        if self.running:
            raise RuntimeError(f"the server on port {self.port} is running already")
        first = not (self.data / "PG_VERSION").is_file()
        if first:
            self._init_cluster(timeout)
        # a free port may be taken between free_port() and the server's bind: the first start
        # tries others; a restart keeps its port (the URL handed out)
        attempts = 3 if self.port is None else 1
        for attempt in range(attempts):
            if self.port is None:
                self.port = free_port()
            self._spawn()
            try:
                wait_for(self._ready, timeout, f"PostgreSQL to accept connections on {self.port}")
                break
            except _PortTaken:
                self.process = None
                if attempt == attempts - 1:
                    raise RuntimeError(self._failure(f"port {self.port} is taken")) from None
                self.port = None
            except TimeoutError as error:
                self._kill_process()
                raise TimeoutError(self._failure(str(error))) from None
        if first:
            with psycopg.connect(self.database_url("postgres"), autocommit=True) as connection:
                connection.execute(f"CREATE DATABASE {DATABASE}")
        return self

    def stop(self, timeout: float = 30.0) -> None:
        """Stop the server (SIGINT: PostgreSQL's fast shutdown, which ends open sessions and
        writes a checkpoint) and wait for it; nothing where it does not run."""
        if self.process is None:
            return
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self._kill_process()
                raise TimeoutError(
                    self._failure(f"PostgreSQL did not shut down within {timeout:g} s")
                ) from None
        self.process = None

    def kill(self, timeout: float = 10.0) -> None:
        """The database dies: SIGKILL to the postmaster, as the kernel's OOM killer or a lost
        machine ends it; no shutdown code runs. Returns once its backends have noticed and
        exited, so that sessions fail from then on and :meth:`restart` finds the data free;
        a later start recovers from the write-ahead log as after any crash."""
        if self.process is None:
            return
        children = _children(self.process.pid)
        self._kill_process()
        wait_for(
            lambda: not any(_alive(pid) for pid in children),
            timeout,
            "the killed server's backends to exit",
            0.02,
        )

    def restart(self, timeout: float = 30.0) -> PostgresServer:
        """Start again on the same port with the same data (stopping it first if it runs)."""
        self.stop(timeout)
        return self.start(timeout)

    def __enter__(self) -> PostgresServer:
        if not self.running:
            self.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.stop()

    # --- logs

    def log(self) -> str:
        """Everything ``initdb`` and the server have logged."""
        return self.log_path.read_text(errors="replace") if self.log_path.is_file() else ""

    def log_tail(self, lines: int = 30) -> str:
        """The last ``lines`` lines of the log."""
        return "\n".join(self.log().splitlines()[-lines:])

    # --- the rest

    def _run_options(self) -> dict[str, Any]:
        """``subprocess`` options common to ``initdb`` and ``postgres``."""
        global _libc
        if _libc is None and sys.platform == "linux":
            with contextlib.suppress(OSError):
                _libc = ctypes.CDLL(None, use_errno=True)  # loaded here, not after the fork
        # PG* variables (PGDATA, PGPORT, PGOPTIONS...) of the caller's must not steer the server
        env = {key: value for key, value in os.environ.items() if not key.startswith("PG")}
        options: dict[str, Any] = {"cwd": self.folder, "env": env, "stdin": subprocess.DEVNULL}
        if self._user is not None:
            uid, gid = self._user
            options.update(user=uid, group=gid, extra_groups=[])
        return options

    def _init_cluster(self, timeout: float) -> None:
        """Find the programs, make the folders (theirs, as root) and run ``initdb``."""
        self._bin = find_binaries()
        for folder in (self.data, self.socket_folder):
            folder.mkdir(mode=0o700, exist_ok=True)
        if self._user is not None:
            self._reach_as_user()
        with self.log_path.open("ab") as log:
            command = [str(self._bin / "initdb"), "--pgdata", str(self.data)]
            command += ["--username", SUPERUSER, "--auth", "trust", "--encoding", "UTF8"]
            command += ["--locale", "C", "--no-sync", "--no-instructions"]
            result = subprocess.run(
                command,
                stdout=log,
                stderr=subprocess.STDOUT,
                timeout=timeout,
                **self._run_options(),
            )
        if result.returncode != 0:
            raise RuntimeError(self._failure(f"initdb exited with {result.returncode}"))

    def _reach_as_user(self) -> None:
        """As root: the folders the server's user's, the programs within its reach."""
        assert self._user is not None and self._bin is not None
        uid, gid = self._user
        blocked = _denied(self.folder, uid, gid)
        if blocked == self.folder:  # a mkdtemp() folder: 700; let others pass, not list
            self.folder.chmod(self.folder.stat().st_mode | 0o011)
        elif blocked is not None:
            raise PermissionError(
                f"{blocked} (mode {blocked.stat().st_mode & 0o7777:o}) keeps uid {uid} out of "
                f"{self.folder}, where PostgreSQL must run as that user: use a folder it can "
                "reach (tempfile.mkdtemp(), not pytest's tmp_path under /tmp/pytest-of-root)"
            )
        for folder in (self.data, self.socket_folder):
            os.chown(folder, uid, gid)
        if _denied(self._bin / "postgres", uid, gid) is not None:
            if os.environ.get(BIN_ENV):
                raise PermissionError(
                    f"uid {uid} may not run {self._bin / 'postgres'} ({BIN_ENV}): "
                    "put the programs where that user can reach them"
                )
            self._bin = _private_install(self._bin, self.folder / "programs")

    def _spawn(self) -> None:
        assert self.port is not None
        if self._bin is None:  # a cluster left by another PostgresServer of the folder
            self._bin = find_binaries()
            if self._user is not None:
                self._reach_as_user()
        command = [str(self._bin / "postgres"), "-D", str(self.data)]
        settings = {
            **SETTINGS,
            "port": str(self.port),
            "unix_socket_directories": str(self.socket_folder),
        }
        for name, value in settings.items():
            command += ["-c", f"{name}={value}"]
        self._log_start = self.log_path.stat().st_size if self.log_path.exists() else 0
        with self.log_path.open("ab") as log:
            self.process = subprocess.Popen(
                command,
                stdout=log,
                stderr=subprocess.STDOUT,
                preexec_fn=_die_with_parent,
                **self._run_options(),
            )

    def _ready(self) -> bool:
        """Whether the postmaster says it is ready (line 8 of ``postmaster.pid``, PostgreSQL
        10 on); raises where it has exited."""
        assert self.process is not None
        if self.process.poll() is not None:
            with self.log_path.open("rb") as log:
                log.seek(self._log_start)
                this_start = log.read().decode(errors="replace")
            if "Address already in use" in this_start:
                raise _PortTaken
            raise RuntimeError(self._failure(f"PostgreSQL exited with {self.process.returncode}"))
        try:
            lines = (self.data / "postmaster.pid").read_text().splitlines()
        except FileNotFoundError:
            return False
        return len(lines) >= 8 and lines[0] == str(self.process.pid) and lines[7].strip() == "ready"

    def _kill_process(self) -> None:
        if self.process is not None:
            if self.process.poll() is None:
                self.process.kill()
            self.process.wait()
            self.process = None

    def _failure(self, what: str) -> str:
        return f"{what}; {self.log_path} ends with:\n{self.log_tail()}"


@contextlib.contextmanager
def running_postgres() -> Iterator[PostgresServer]:
    """A started server in a folder of :func:`tempfile.mkdtemp` (as root the server runs as
    ``nobody``, who cannot reach pytest's ``tmp_path``), stopped and removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="vtrack-postgres-"))
    server = PostgresServer(folder)
    try:
        yield server.start()
    finally:
        server.stop()
        shutil.rmtree(folder, ignore_errors=True)


class _PortTaken(Exception):
    """The server could not bind its port (taken since :func:`free_port` found it free)."""


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (a postmaster's backends and helpers)."""
    children = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                # the name, in parentheses, may hold spaces and parentheses
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                if int(fields[1]) == pid:
                    children.append(int(entry.name))
    return children


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs; a zombie (exited, not yet reaped by its new parent) is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
