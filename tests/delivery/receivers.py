"""A webhook receiver on loopback and events to send it, for the delivery tests."""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import subprocess
import sys
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from devtools.testing import free_port
from service.delivery.outbox import OutgoingEvent
from service.delivery.sinks import KEY_HEADER, SIGNATURE_HEADER

SECRET = "s3cret"


def events(n: int, camera: str = "gate") -> list[OutgoingEvent]:
    return [
        OutgoingEvent(
            key=f"{camera}-{i}",
            topic=f"cameras/{camera}/events/line_crossed",
            body=json.dumps({"type": "line_crossed", "n": i}),
        )
        for i in range(n)
    ]


class Receiver:
    """A webhook receiver on loopback: records what it is sent, checks the signature."""

    def __init__(self, port: int) -> None:
        self.received: list[tuple[str, dict]] = []
        self.bad_signatures = 0
        receiver = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                expected = "sha256=" + hmac.new(SECRET.encode(), body, hashlib.sha256).hexdigest()
                if not hmac.compare_digest(self.headers.get(SIGNATURE_HEADER, ""), expected):
                    receiver.bad_signatures += 1
                receiver.received.append((self.headers[KEY_HEADER], json.loads(body)))
                self.send_response(204)
                self.end_headers()

            def log_message(self, *args) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@contextlib.contextmanager
def mqtt_broker(folder: Path) -> Iterator[int]:
    """An MQTT broker (amqtt, from PyPI) on a loopback port, in a process of its own; yields
    its port."""
    port = free_port()
    config = folder / "broker.yaml"
    config.write_text(
        "listeners:\n  default:\n    type: tcp\n"
        f"    bind: 127.0.0.1:{port}\n"
        "plugins:\n  amqtt.plugins.authentication.AnonymousAuthPlugin:\n"
        "    allow_anonymous: true\n"
    )
    with (folder / "broker.log").open("w") as log:
        process = subprocess.Popen(
            [sys.executable, "-c", "from amqtt.scripts.broker_script import main; main()",
             "-c", str(config)],
            stdout=log,
            stderr=subprocess.STDOUT,
        )  # fmt: skip
        try:
            yield port
        finally:
            process.terminate()
            process.wait(10)
