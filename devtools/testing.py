"""``vtrack serve`` in a subprocess on loopback ports, as the tests and benchmarks run it.

The server is started the way users start it (``python -m service.cli serve``) with settings
from ``VTRACK_*`` environment variables; the HTTP port and the Zenoh listen port are free ports
picked here, so two servers of parallel tests or benchmarks never meet. Waits poll a condition
with a deadline instead of sleeping for a fixed time.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import httpx

__all__ = ["Server", "free_port", "try_get", "wait_for"]

_REPO_ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def try_get(url: str, timeout: float = 2.0) -> httpx.Response | None:
    """``GET url``, or ``None`` while nothing answers there (a server still starting)."""
    try:
        return httpx.get(url, timeout=timeout)
    except httpx.TransportError:
        return None


def wait_for(
    condition: Callable[[], object], timeout: float, what: str, interval: float = 0.1
) -> object:
    """Poll ``condition`` until it returns something truthy and return that.

    Raises
    ------
    TimeoutError
        After ``timeout`` seconds, naming ``what`` was awaited.
    """
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


class Server:
    """``vtrack serve`` with its data in ``data_dir``, on a loopback port.

    Parameters
    ----------
    data_dir:
        The service's data directory (created by the service).
    workers:
        Job worker processes (``--workers``); ``None``: the service's default.
    log_level:
        ``--log-level``. The log goes to ``<data_dir>-server.log`` beside ``data_dir``.
    file_size_limit:
        Largest file in bytes the service and its workers may write (``ulimit -f``): beyond
        it a write fails with ``EFBIG``, as a full disk fails one with ``ENOSPC``.
    prefix:
        Command words before the service's (``setpriv`` options that take root's power to
        write through file modes, say).
    own_group:
        Start the service in a process group of its own, which :meth:`signal_group` signals
        as a service manager or a terminal's Ctrl-C does.
    name:
        The log's name, ``<name>-server.log`` (default: the data folder's): instances that
        share a data folder keep logs of their own.
    **settings:
        Service settings by name, passed as ``VTRACK_<NAME>`` (``api_token="..."``,
        ``zenoh_listen='["tcp/..."]'``...). ``zenoh_listen`` defaults to a free loopback port.
    """

    def __init__(
        self,
        data_dir: Path,
        workers: int | None = 2,
        log_level: str = "info",
        file_size_limit: int | None = None,
        prefix: tuple[str, ...] = (),
        own_group: bool = False,
        name: str | None = None,
        **settings: object,
    ) -> None:
        self.data_dir = data_dir
        self.prefix = prefix
        self.own_group = own_group
        self.file_size_limit = file_size_limit
        self.workers = workers
        self.log_level = log_level
        self._own_zenoh_port = "zenoh_listen" not in settings
        settings.setdefault("zenoh_listen", json.dumps([f"tcp/127.0.0.1:{free_port()}"]))
        self.settings = settings
        self.token = settings.get("api_token")
        self.port = free_port()
        self.log_path = data_dir.parent / f"{name or data_dir.name}-server.log"
        self.process: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def zenoh_listen(self) -> tuple[str, ...]:
        """The Zenoh endpoints the service listens on."""
        return tuple(json.loads(str(self.settings["zenoh_listen"])))

    def client(self, token: str | None = None, **kwargs: object) -> httpx.Client:
        """An HTTP client for the server, with the API token when one is set."""
        token = token if token is not None else self.token
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        kwargs.setdefault("timeout", 30.0)
        return httpx.Client(base_url=self.url, headers=headers, **kwargs)

    def start(self, timeout: float = 60.0, ready: bool = True, attempts: int = 3) -> Server:
        """Start the service and wait until ``/readyz`` answers 200 (``ready``) or, for a
        service expected not to be ready, until ``/healthz`` answers.

        A port found free by :func:`free_port` may be taken by another process before the
        service binds it (parallel tests open many connections): when the service says so
        and exits, it is started again on fresh ports, up to ``attempts`` times.
        """
        for attempt in range(1, attempts + 1):
            log_start = self.log_path.stat().st_size if self.log_path.is_file() else 0
            try:
                return self._start_once(timeout, ready)
            except RuntimeError:
                with self.log_path.open("rb") as log:
                    log.seek(log_start)
                    taken = b"Address already in use" in log.read()
                if not taken or attempt == attempts:
                    raise
                self.port = free_port()
                if self._own_zenoh_port:
                    endpoint = f"tcp/127.0.0.1:{free_port()}"
                    self.settings["zenoh_listen"] = json.dumps([endpoint])
        raise AssertionError("unreachable")

    def _start_once(self, timeout: float, ready: bool) -> Server:
        env = {k: v for k, v in os.environ.items() if not k.startswith("VTRACK_")}
        env.update({f"VTRACK_{k.upper()}": str(v) for k, v in self.settings.items()})
        command = [*self.prefix, sys.executable, "-m", "service.cli", "serve"]
        command += ["--host", "127.0.0.1", "--port", str(self.port)]
        command += ["--data-dir", str(self.data_dir), "--log-level", self.log_level]
        if self.workers is not None:
            command += ["--workers", str(self.workers)]
        with self.log_path.open("a") as log:
            self.process = subprocess.Popen(
                command,
                cwd=_REPO_ROOT,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                preexec_fn=self._limit_file_size if self.file_size_limit else None,
                start_new_session=self.own_group,
            )
        check = self._ready if ready else self._answers
        wait_for(check, timeout, f"the server on port {self.port} to answer", 0.1)
        return self

    def _limit_file_size(self) -> None:
        # Python ignores SIGXFSZ, so a write beyond the limit raises OSError(EFBIG).
        limit = int(self.file_size_limit or 0)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    def _ready(self) -> bool:
        return self._answers("/readyz")

    def _answers(self, path: str = "/healthz") -> bool:
        if self.process is not None and self.process.poll() is not None:
            raise RuntimeError(f"the server exited early:\n{self.log_tail()}")
        response = try_get(f"{self.url}{path}")
        return response is not None and response.status_code == 200

    def log(self) -> str:
        """Everything the server has logged."""
        return self.log_path.read_text(errors="replace") if self.log_path.is_file() else ""

    def log_tail(self, lines: int = 40) -> str:
        """The last ``lines`` lines of the log."""
        return "\n".join(self.log().splitlines()[-lines:])

    def stop(self) -> None:
        """A clean stop (SIGTERM), as a service manager does."""
        if self.process is None or self.process.poll() is not None:
            return
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10)

    def signal_group(self, sig: int) -> None:
        """Send ``sig`` to every process of the service (started with ``own_group``)."""
        if not self.own_group or self.process is None:
            raise RuntimeError("signal_group needs a server started with own_group=True")
        os.killpg(self.process.pid, sig)

    def kill(self) -> None:
        """The service dies (SIGKILL): no shutdown code runs."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)
