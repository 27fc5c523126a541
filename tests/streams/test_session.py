"""Zenoh session configuration (service.streams.session): the hub, members, clients and
their security, and what a session does at its limits."""

from __future__ import annotations

import dataclasses
import json
import socket

import pytest
import zenoh

from devtools.testing import free_port, wait_for
from service.streams.security import AccessRules, TlsFiles, ZenohSecurity
from service.streams.session import (
    ZenohOptions,
    ZenohUnavailable,
    open_session,
    wait_for_neighbour,
)


def config_value(config: zenoh.Config, key: str):
    """``get_json`` answers with a JSON string (checked here once, so a change shows)."""
    text = config.get_json(key)
    assert isinstance(text, str)
    return json.loads(text)


def client_listens(config: zenoh.Config) -> list[str]:
    """What a client-mode session listens on: the default is per mode and has no client entry."""
    listen = config_value(config, "listen/endpoints")
    if isinstance(listen, dict):
        return listen.get("client") or []
    return listen


def test_hub_config_peer():
    options = ZenohOptions(listen=("tcp/0.0.0.0:7500",), connect=("tcp/10.0.0.1:7447",))
    config = options.hub_config()
    assert config_value(config, "mode") == "peer"
    assert config_value(config, "listen/endpoints") == ["tcp/0.0.0.0:7500"]
    assert config_value(config, "connect/endpoints") == ["tcp/10.0.0.1:7447"]
    assert config_value(config, "scouting/multicast/enabled") is False


def test_hub_config_defaults():
    config = ZenohOptions().hub_config()
    assert config_value(config, "mode") == "peer"
    assert config_value(config, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    assert config_value(config, "connect/endpoints") == []
    assert config_value(config, "scouting/multicast/enabled") is False


def test_member_config_peer():
    options = ZenohOptions(
        listen=("tcp/0.0.0.0:7500", "tcp/[::]:7501", "tcp/192.168.1.2:7502"),
        connect=("tcp/10.0.0.1:7447",),
    )
    config = options.member_config()
    assert config_value(config, "mode") == "peer"
    assert config_value(config, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    assert config_value(config, "connect/endpoints") == [
        "tcp/127.0.0.1:7500",
        "tcp/127.0.0.1:7501",
        "tcp/192.168.1.2:7502",
        "tcp/10.0.0.1:7447",
    ]
    assert config_value(config, "scouting/multicast/enabled") is False


def test_member_config_defaults_connect_to_the_default_hub():
    config = ZenohOptions().member_config()
    assert config_value(config, "connect/endpoints") == ["tcp/127.0.0.1:7447"]
    assert config_value(config, "listen/endpoints") == ["tcp/127.0.0.1:0"]


def test_client_mode_configs():
    options = ZenohOptions(
        mode="client", listen=("tcp/127.0.0.1:7500",), connect=("tcp/10.0.0.1:7447",)
    )
    for config in (options.hub_config(), options.member_config()):
        assert config_value(config, "mode") == "client"
        assert client_listens(config) == []
        assert config_value(config, "connect/endpoints") == ["tcp/10.0.0.1:7447"]
        assert config_value(config, "scouting/multicast/enabled") is False


def test_secured_configs_make_the_hub_a_router_and_the_members_its_clients(tmp_path):
    # In peer mode two peers can meet around the hub's rules; through a router they cannot.
    rules = AccessRules.from_maps("vtrack", "svc", {"cam": ["gate"]}, {})
    security = ZenohSecurity(
        TlsFiles(tmp_path / "s.pem", tmp_path / "s.key", tmp_path / "ca.pem"),
        user="svc",
        password="pw",
        users_file=tmp_path / "users.txt",
        access=rules,
    )
    options = ZenohOptions(listen=("tls/127.0.0.1:7500",), security=security)
    hub, member = options.hub_config(), options.member_config()
    assert config_value(hub, "mode") == "router" and config_value(member, "mode") == "client"
    assert client_listens(member) == []
    assert config_value(member, "connect/endpoints") == ["tls/127.0.0.1:7500"]
    assert config_value(hub, "transport/link/tls/listen_certificate") == str(tmp_path / "s.pem")
    assert config_value(member, "transport/link/tls/listen_certificate") is None
    assert config_value(member, "transport/link/tls/root_ca_certificate") == str(
        tmp_path / "ca.pem"
    )
    assert config_value(hub, "transport/auth/usrpwd/dictionary_file") == str(tmp_path / "users.txt")
    assert config_value(member, "transport/auth/usrpwd/dictionary_file") is None
    assert config_value(member, "transport/auth/usrpwd/user") == "svc"
    assert config_value(hub, "access_control/enabled") is True
    assert config_value(member, "access_control/enabled") is False
    # a client of a separate router presents its credentials; the rules are the router's
    client = dataclasses.replace(options, mode="client", connect=("tls/10.0.0.1:7447",))
    assert config_value(client.hub_config(), "access_control/enabled") is False
    assert config_value(client.hub_config(), "mode") == "client"


def test_a_message_over_the_size_limit_is_dropped_and_the_link_stays():
    # Zenoh's default takes messages up to 1 GiB, put together in memory before any check
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hub = open_session(ZenohOptions(listen=(endpoint,), max_message_size=2**20).hub_config())
    member = open_session(ZenohOptions(listen=(endpoint,)).member_config())
    try:
        sizes: list[int] = []
        hub.declare_subscriber("limit/test", lambda sample: sizes.append(len(sample.payload)))
        assert wait_for_neighbour(member, 5)
        wait_for(lambda: member.put("limit/test", b"x") or sizes, 10, "the first message")
        member.put("limit/test", b"x" * 2**21)
        # blocking, not the default dropping: on a busy machine the large message's fragments
        # may still fill the sender's queue, which would drop this one before the link saw it
        member.put("limit/test", b"x" * 200, congestion_control=zenoh.CongestionControl.BLOCK)
        wait_for(lambda: 200 in sizes, 10, "the message after the large one")
        assert 2**21 not in sizes
    finally:
        member.close()
        hub.close()


def test_open_session_on_a_busy_port():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        config = ZenohOptions(listen=(f"tcp/127.0.0.1:{port}",)).hub_config()
        with pytest.raises(ZenohUnavailable) as error:
            open_session(config)
    message = str(error.value)
    assert "address already in use" in message.lower() or "address in use" in message.lower()
    assert str(port) in message
    assert " at /" not in message  # Zenoh's source locations are cut off
