"""Zenoh session configuration for the service process, its stream workers and the CLI tools.

The service process opens the *hub* session: in peer mode it listens on ``VTRACK_ZENOH_LISTEN``
(loopback by default), so cameras, stream workers and subscribers on this machine find each
other through it without multicast scouting and without a router. Every other session connects
to the hub (and to ``VTRACK_ZENOH_CONNECT``, e.g. the compose file's router) and, in peer mode,
listens on an ephemeral loopback port so that the peers it learns of by gossip can reach it
directly. A forked session is dead, so each worker opens its own after it starts
(docs/architecture.md §7).

With TLS, authentication or access control configured (:mod:`service.streams.security`) the hub
is a router and every other session its client, so that no two sessions meet around its rules.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import zenoh

from service.streams.security import ZenohSecurity

DEFAULT_LISTEN = ("tcp/127.0.0.1:7447",)

MESSAGE_MARGIN = 1024**2
"""Bytes a Zenoh message may carry beyond the frame limit (attachment, encoding, headers)."""


@dataclass(frozen=True, slots=True)
class ZenohOptions:
    """How to reach the Zenoh network (picklable: it crosses the process boundary).

    Attributes
    ----------
    mode:
        ``"peer"`` (default) or ``"client"`` (everything goes through a router).
    listen:
        Endpoints the hub session listens on.
    connect:
        Endpoints every session connects to (a router, other hubs).
    config_file:
        A Zenoh JSON5 configuration to start from; the fields above are applied over it.
    security:
        TLS, credentials and access rules.
    max_message_size:
        The largest message a session takes off a link, in bytes (Zenoh's default is 1 GiB;
        a larger sample is dropped by Zenoh before it is reassembled in memory).
    """

    mode: Literal["peer", "client"] = "peer"
    listen: tuple[str, ...] = DEFAULT_LISTEN
    connect: tuple[str, ...] = ()
    config_file: Path | None = field(default=None)
    security: ZenohSecurity = field(default_factory=ZenohSecurity)
    max_message_size: int | None = None

    @property
    def hub_mode(self) -> Literal["peer", "client", "router"]:
        """The hub's Zenoh mode: a router where security is configured (see the module)."""
        return "router" if self.mode == "peer" and self.security.configured else self.mode

    def hub_config(self) -> zenoh.Config:
        """The service process's session: listens for the others (``ZenohUnavailable`` for a
        configuration Zenoh refuses)."""
        with _reported():
            config = self._base(self.hub_mode)
            if self.mode == "peer" and self.listen:
                config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
            if self.connect:
                config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
            # a client of a separate router presents credentials; that router has the rules
            self.security.apply(config, hub=self.mode == "peer")
        return config

    def member_config(self) -> zenoh.Config:
        """A stream worker's or a CLI tool's session: connects to the hub and the router."""
        with _reported():
            peer = self.mode == "peer" and not self.security.configured
            config = self._base("peer" if peer else "client")
            if peer:
                config.insert_json5("listen/endpoints", json.dumps(["tcp/127.0.0.1:0"]))
            if endpoints := self.member_endpoints():
                config.insert_json5("connect/endpoints", json.dumps(endpoints))
            self.security.apply(config, hub=False)
        return config

    def member_endpoints(self) -> list[str]:
        """The endpoints a member session connects to: the hub (in peer mode), then ``connect``."""
        hub = [_reachable(e) for e in self.listen] if self.mode == "peer" else []
        return [*hub, *self.connect]

    def _base(self, mode: str) -> zenoh.Config:
        config = load_config_file(self.config_file) if self.config_file else zenoh.Config()
        config.insert_json5("mode", json.dumps(mode))
        if self.max_message_size is not None:
            config.insert_json5("transport/link/rx/max_message_size", str(self.max_message_size))
        # Multicast scouting would make every instance on the LAN talk to every camera: off,
        # unless a configuration file turns it on.
        if self.config_file is None:
            config.insert_json5("scouting/multicast/enabled", "false")
        return config


_ENDPOINT = re.compile(r"^[a-z][a-z0-9\-]*/\S+$")


def zenoh_endpoint(text: str) -> str:
    """``text`` if it has the form of a Zenoh endpoint, ``<protocol>/<address>``, else
    ValueError (Zenoh's own error comes only when a session opens, in Rust's words)."""
    if not _ENDPOINT.match(text):
        raise ValueError(
            f"{text!r} is not a Zenoh endpoint: write <protocol>/<address>, e.g. tcp/127.0.0.1:7447"
        )
    return text


def endpoint_address(endpoint: str) -> str | None:
    """The address an endpoint ``<protocol>/<address>:<port>[?metadata][#config]`` names
    (``0.0.0.0``, ``[::1]``, a host name); None for a Unix socket's path, local by nature."""
    protocol, _, rest = endpoint.partition("/")
    if protocol == "unixsock-stream":
        return None
    return re.split(r"[?#]", rest)[0].rpartition(":")[0]


def _reachable(endpoint: str) -> str:
    """A listen endpoint as another local process connects to it (0.0.0.0 -> 127.0.0.1)."""
    for wildcard in ("0.0.0.0", "[::]"):
        endpoint = endpoint.replace(f"/{wildcard}:", "/127.0.0.1:")
    return endpoint


def load_config_file(path: Path) -> zenoh.Config:
    """A Zenoh JSON5 or YAML configuration file (``ZenohUnavailable`` when Zenoh refuses it)."""
    with _reported(f"{path}: "):
        return zenoh.Config.from_file(str(path))


def open_session(config: zenoh.Config) -> zenoh.Session:
    """Open a session; Zenoh's error (a busy port, no router) comes back as ``ZenohUnavailable``."""
    with _reported():
        return zenoh.open(config)


def wait_for_neighbour(session: zenoh.Session, timeout: float) -> bool:
    """Whether ``session`` is connected to a peer or a router within ``timeout`` seconds.

    A peer session opens even when nothing answers at its endpoints (Zenoh keeps trying them
    in the background), so without this a camera publishing to a mistyped endpoint would look
    like one that nobody subscribes to.
    """
    deadline = time.monotonic() + timeout
    while True:
        if list(session.info.peers_zid()) or list(session.info.routers_zid()):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.05)


@contextmanager
def _reported(context: str = "") -> Iterator[None]:
    """Zenoh's errors as ``ZenohUnavailable``, in words for users."""
    try:
        yield
    except zenoh.ZError as error:
        # Zenoh's messages end with source locations ("at /root/.cargo/..."): not for users.
        message = re.sub(r"\s+at /[^\s\]]+", "", str(error)).strip()
        raise ZenohUnavailable(context + message) from None


class ZenohUnavailable(RuntimeError):
    """The Zenoh session could not be opened."""
