"""``vtrack serve`` in a subprocess on loopback ports, for the benchmarks that need a server.

Settings come from ``VTRACK_*`` environment variables as users give them; the HTTP port and the
Zenoh listen port are free ports picked here, so a benchmark never meets another service.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import httpx

REPO_ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def wait_for(condition: Callable[[], object], timeout: float, what: str, interval: float = 0.1):
    """Poll ``condition`` until it returns something truthy; TimeoutError after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


class Server:
    """``vtrack serve`` with its data in ``scratch``; :meth:`stop` sends SIGTERM."""

    def __init__(
        self, scratch: Path, workers: int | None = 1, log_level: str = "info", **settings: str
    ) -> None:
        self.scratch = scratch
        self.port = free_port()
        self.zenoh_endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.workers = workers
        self.log_level = log_level
        self.settings = settings
        self.log_path = scratch / "server.log"
        self.process: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout: float = 120.0) -> Server:
        env = {k: v for k, v in os.environ.items() if not k.startswith("VTRACK_")}
        env["VTRACK_ZENOH_LISTEN"] = json.dumps([self.zenoh_endpoint])
        env.update({f"VTRACK_{k.upper()}": v for k, v in self.settings.items()})
        command = [sys.executable, "-m", "service.cli", "serve", "--host", "127.0.0.1"]
        command += ["--port", str(self.port), "--data-dir", str(self.scratch / "data")]
        command += ["--log-level", self.log_level]
        if self.workers:
            command += ["--workers", str(self.workers)]
        with self.log_path.open("w") as log:
            self.process = subprocess.Popen(
                command, cwd=REPO_ROOT, env=env, stdout=log, stderr=subprocess.STDOUT
            )
        wait_for(self._ready, timeout, f"the server on port {self.port}", interval=0.2)
        return self

    def _ready(self) -> bool:
        if self.process is not None and self.process.poll() is not None:
            raise RuntimeError(f"the server exited early:\n{self.log_tail()}")
        try:
            return httpx.get(f"{self.url}/readyz", timeout=2.0).status_code == 200
        except httpx.TransportError:
            return False

    def log_tail(self, lines: int = 40) -> str:
        if not self.log_path.is_file():
            return ""
        return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self) -> None:
        if self.process is None or self.process.poll() is not None:
            return
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout=10)
