"""Where events go: webhooks (HTTP POST of JSON, signed) and an MQTT broker (QoS 1).

A sink sends one event and returns once the receiver has it (a 2xx answer; the broker's
PUBACK), or raises :class:`DeliveryError`; retrying is the dispatcher's business
(:mod:`service.delivery.dispatch`), and so is never blocking the tracking.
"""

from __future__ import annotations

import hashlib
import hmac
import threading
from dataclasses import dataclass
from typing import Protocol
from urllib.parse import urlsplit

import httpx

from service.delivery.outbox import OutboxEvent

__all__ = ["DeliveryError", "MqttSink", "Sink", "WebhookSink", "signature"]

SIGNATURE_HEADER = "X-Vtrack-Signature"
"""``sha256=<hex>``: HMAC-SHA256 of the request body with the webhook's secret."""
KEY_HEADER = "Idempotency-Key"
"""The event's key: the same event sent twice (a retry after a lost answer) has the same."""
TOPIC_HEADER = "X-Vtrack-Topic"
"""What the event is about: ``cameras/<camera>/events/<type>``, ``jobs/<id>/finished``: the
MQTT topic without the sink's prefix."""


class DeliveryError(Exception):
    """The receiver did not take the event (down, refused, timed out)."""


class Sink(Protocol):
    """A receiver of events."""

    name: str

    def send(self, event: OutboxEvent) -> None:
        """Deliver ``event`` or raise :class:`DeliveryError`."""
        ...

    def close(self) -> None: ...


def signature(secret: str, body: bytes) -> str:
    """The value of :data:`SIGNATURE_HEADER` for ``body``: ``sha256=`` and the hex HMAC-SHA256
    of the body keyed with ``secret`` (RFC 2104), as GitHub's and Stripe's webhooks sign."""
    return "sha256=" + hmac.new(secret.encode(), body, hashlib.sha256).hexdigest()


@dataclass
class WebhookSink:
    """POSTs each event's JSON body to ``url``; signed when a ``secret`` is set."""

    name: str
    url: str
    secret: str | None = None
    timeout: float = 10.0

    def __post_init__(self) -> None:
        self._client = httpx.Client(timeout=self.timeout, follow_redirects=False)

    def send(self, event: OutboxEvent) -> None:
        body = event.body.encode()
        headers = {
            "Content-Type": "application/json",
            KEY_HEADER: event.key,
            TOPIC_HEADER: event.topic,
        }
        if self.secret:
            headers[SIGNATURE_HEADER] = signature(self.secret, body)
        try:
            response = self._client.post(self.url, content=body, headers=headers)
        except httpx.HTTPError as error:
            raise DeliveryError(f"{type(error).__name__}: {error}") from None
        if not response.is_success:
            raise DeliveryError(f"the receiver answered {response.status_code}")

    def close(self) -> None:
        self._client.close()


class MqttSink:
    """Publishes each event with QoS 1 on ``<topic_prefix>/<its topic>`` to the broker at
    ``url`` (``mqtt://[user:password@]host[:port]``, ``mqtts://`` for TLS).

    paho-mqtt's network loop runs in a thread of its own and reconnects by itself; a publish
    waits for the broker's PUBACK at most ``timeout`` seconds.
    """

    def __init__(
        self, name: str, url: str, topic_prefix: str = "vtrack", timeout: float = 10.0
    ) -> None:
        import paho.mqtt.client as mqtt

        self.name = name
        self.topic_prefix = topic_prefix.strip("/")
        self.timeout = timeout
        parts = urlsplit(url)
        if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
            raise ValueError(f"an MQTT broker's address is mqtt://host[:port], not {url!r}")
        self._connected = threading.Event()
        self._client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"vtrack-{name}")
        if parts.username:
            self._client.username_pw_set(parts.username, parts.password)
        if parts.scheme == "mqtts":
            self._client.tls_set()
        self._client.on_connect = lambda *args: self._connected.set()
        self._client.on_disconnect = lambda *args: self._connected.clear()
        self._client.reconnect_delay_set(min_delay=1, max_delay=30)
        port = parts.port or (8883 if parts.scheme == "mqtts" else 1883)
        self._client.connect_async(parts.hostname, port, keepalive=30)
        self._client.loop_start()

    def send(self, event: OutboxEvent) -> None:
        if not self._connected.wait(self.timeout):
            raise DeliveryError("the MQTT broker is not connected")
        topic = f"{self.topic_prefix}/{event.topic}" if self.topic_prefix else event.topic
        info = self._client.publish(topic, event.body.encode(), qos=1)
        try:
            info.wait_for_publish(self.timeout)
        except (RuntimeError, ValueError) as error:  # not queued: the connection went away
            raise DeliveryError(f"the MQTT broker did not take it: {error}") from None
        if not info.is_published():
            raise DeliveryError(f"the MQTT broker did not acknowledge it in {self.timeout:g} s")

    def close(self) -> None:
        self._client.disconnect()
        self._client.loop_stop()
