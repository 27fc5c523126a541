"""``vtrack zenoh certificates`` and ``vtrack zenoh router-config``: what a site needs to run the
live streams' Zenoh links with TLS, authentication and access control (docs/service.md,
Security)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from service.streams.session import zenoh_endpoint

DEFAULT_HOSTS = ("127.0.0.1", "localhost")


def add_command(commands: argparse._SubParsersAction) -> None:
    """The ``zenoh`` command and its ``certificates`` and ``router-config`` actions."""
    zenoh = commands.add_parser(
        "zenoh",
        help="certificates and a router configuration for secured live streams",
        description="Make a local certificate authority and certificates for Zenoh's TLS, and "
        "write the configuration of a Zenoh router (zenohd) that enforces this service's "
        "access rules (VTRACK_ZENOH_* settings).",
    )
    actions = zenoh.add_subparsers(dest="zenoh_command", required=True, metavar="ACTION")
    certificates = actions.add_parser(
        "certificates",
        help="make a local CA and TLS certificates",
        description="Make FOLDER/ca.pem and ca.key (once: later runs sign with them) and a "
        "certificate and key, NAME.pem and NAME.key, for the service and for each --client. "
        "Files already there are kept. Give the CA's ca.pem to every camera and reader "
        "(VTRACK_ZENOH_TLS_ROOT_CA) and keep ca.key private.",
    )
    certificates.add_argument("folder", type=Path, metavar="FOLDER")
    certificates.add_argument(
        "--name", default="vtrack", help="common name of the service's certificate (vtrack)"
    )
    certificates.add_argument(
        "--host",
        action="append",
        metavar="HOST",
        help="a host name or address cameras reach the service at (repeatable; default "
        f"{', '.join(DEFAULT_HOSTS)}; give the names and addresses of this machine too)",
    )
    certificates.add_argument(
        "--client",
        action="append",
        default=[],
        metavar="NAME",
        help="a certificate for a camera, gateway or reader with this common name (its "
        "principal under mutual TLS; repeatable)",
    )
    certificates.set_defaults(handler=_certificates)
    router = actions.add_parser(
        "router-config",
        help="write a Zenoh router configuration with this service's rules",
        description="Write the JSON5 configuration of a zenohd router that enforces the rules "
        "of the VTRACK_ZENOH_* settings (TLS files, users file, VTRACK_ZENOH_CAMERAS and "
        "VTRACK_ZENOH_READERS): for a service that reaches its cameras through a router "
        "(VTRACK_ZENOH_MODE=client), as the compose file runs it. File paths are written as "
        "the settings give them: the router must see the files at the same paths.",
    )
    router.add_argument(
        "--listen",
        action="append",
        type=zenoh_endpoint,
        metavar="ENDPOINT",
        help="endpoint the router listens on (repeatable; default tls/0.0.0.0:7447 with a "
        "certificate, else tcp/0.0.0.0:7447)",
    )
    router.add_argument("--out", type=Path, help="file to write (default: standard output)")
    router.set_defaults(handler=_router_config)


def _certificates(args: argparse.Namespace) -> int:
    from service.streams.certificates import make_certificates

    names = {args.name: args.host or list(DEFAULT_HOSTS)}
    for client in args.client:
        if client in names:
            print(f"vtrack zenoh certificates: {client!r} is named twice", file=sys.stderr)
            return 2
        names[client] = []
    try:
        issued = make_certificates(args.folder, names)
    except (OSError, ValueError) as error:
        print(f"vtrack zenoh certificates: {error}", file=sys.stderr)
        return 1
    for item in issued:
        state = "made" if item.created else "kept"
        print(f"{state} {item.certificate} and {item.private_key}")
    return 0


def _router_config(args: argparse.Namespace) -> int:
    from service.settings import InvalidSettings, load_settings
    from service.streams.security import router_config

    try:
        settings = load_settings()
    except InvalidSettings as error:
        for problem in error.problems:
            print(f"vtrack zenoh router-config: {problem}", file=sys.stderr)
        return 2
    security = settings.zenoh_security
    if not security.enforced:
        print(
            "vtrack zenoh router-config: no VTRACK_ZENOH_USERS_FILE and no "
            "VTRACK_ZENOH_TLS_CLIENT_AUTH: a router without authentication would let anyone "
            "publish frames and read tracks",
            file=sys.stderr,
        )
        return 2
    listen = args.listen or ["tls/0.0.0.0:7447" if security.tls.certificate else "tcp/0.0.0.0:7447"]
    if any(e.startswith("tls/") for e in listen) and security.tls.certificate is None:
        print(
            "vtrack zenoh router-config: a tls/ endpoint needs VTRACK_ZENOH_TLS_CERTIFICATE "
            "and VTRACK_ZENOH_TLS_PRIVATE_KEY",
            file=sys.stderr,
        )
        return 2
    text = json.dumps(router_config(security, listen, settings.zenoh.max_message_size), indent=2)
    header = "// Written by `vtrack zenoh router-config` from the VTRACK_ZENOH_* settings.\n"
    if args.out is None:
        print(header + text)
    else:
        args.out.write_text(header + text + "\n", encoding="utf-8")
    return 0
