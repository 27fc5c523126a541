"""``vtrack serve``: the HTTP service, its settings checked and its port taken before it starts."""

from __future__ import annotations

import argparse
import errno
import socket
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from service.settings import Settings


def add_command(commands: argparse._SubParsersAction) -> None:
    """The ``serve`` command and its arguments."""
    serve = commands.add_parser(
        "serve",
        help="start the HTTP service",
        description="Start the HTTP service. Every setting can also come from a VTRACK_* "
        "environment variable (see docs/settings.md); options here win.",
    )
    serve.add_argument("--host", help="address to bind (VTRACK_HOST, default 127.0.0.1)")
    serve.add_argument("--port", type=int, help="port (VTRACK_PORT, default 8000)")
    serve.add_argument(
        "--workers", type=int, help="worker processes (VTRACK_WORKERS, default: cores)"
    )
    serve.add_argument(
        "--data-dir",
        type=Path,
        help="job store and files (VTRACK_DATA_DIR, default: vtrack-data in the current folder)",
    )
    serve.add_argument("--log-level", help="debug, info, warning... (VTRACK_LOG_LEVEL)")
    serve.set_defaults(handler=_serve)


def _serve(args: argparse.Namespace) -> int:
    from service.data_folder import DataFolderError, JobDatabaseError, claim_data_folder
    from service.logs import quiet_ffmpeg, uvicorn_log_config
    from service.settings import InvalidSettings, load_settings
    from service.worker_processes import start_fork_server

    overrides = {
        name: value
        for name, value in (
            ("host", args.host),
            ("port", args.port),
            ("workers", args.workers),
            ("data_dir", args.data_dir),
            ("log_level", args.log_level),
        )
        if value is not None
    }
    try:
        settings = load_settings(overrides)
    except InvalidSettings as error:
        for problem in error.problems:
            print(f"vtrack: {problem}", file=sys.stderr)
        return 2
    try:
        # writable (with its subfolders and job database) and ours alone, locked until we exit
        data_folder = claim_data_folder(settings)
    except JobDatabaseError as error:
        print(f"vtrack: the job database (VTRACK_DATABASE_URL): {error}", file=sys.stderr)
        return 2
    except DataFolderError as error:
        print(f"vtrack: the data folder (--data-dir, VTRACK_DATA_DIR): {error}", file=sys.stderr)
        return 2
    # The port is taken here, before the workers start and "serving" is said: a port in use
    # is then a setting that cannot work, stopped at once like the others.
    family = socket.AF_INET6 if ":" in settings.host else socket.AF_INET
    try:
        listener = socket.create_server((settings.host, settings.port), family=family)
    except OSError as error:
        # create_server words every failure alike; errno tells the port's from the address's
        # (a name that does not resolve has a negative errno, that of getaddrinfo)
        reason = (error.strerror or str(error)).partition(" (while attempting")[0]
        if error.errno in (errno.EADDRINUSE, errno.EACCES):
            problem = (
                f"--port, VTRACK_PORT: cannot listen on {settings.host}:{settings.port} "
                f"({reason}); another program (another vtrack serve?) may use it, or the port "
                "needs privileges (under 1024): stop it or choose another port"
            )
        else:  # not an address of this machine, or a name that does not resolve
            problem = (
                f"--host, VTRACK_HOST: cannot listen on {settings.host!r} ({reason}): give an "
                "address of this machine, e.g. 127.0.0.1, or 0.0.0.0 for all"
            )
        print(f"vtrack: {problem}", file=sys.stderr)
        return 2
    host = settings.host
    # a wildcard address is where the service listens, not an address a browser can open
    wildcard = host in ("0.0.0.0", "::", "")
    url = f"http://{'localhost' if wildcard else f'[{host}]' if ':' in host else host}:"
    url += str(settings.port)
    where = f"every address of this machine, port {settings.port}" if wildcard else url
    workers = f"{settings.workers} worker{'s' if settings.workers != 1 else ''}"
    print(
        f"vtrack: serving on {where} with {workers}, data in {settings.data_dir}\n"
        f"vtrack: open the API docs at {url}/docs (Ctrl-C stops)",
        file=sys.stderr,
        flush=True,
    )
    if settings.zenoh_enabled:
        print(f"vtrack: {_zenoh_posture(settings)}", file=sys.stderr, flush=True)
    for warning in _exposure_warnings(settings, where):
        print(f"vtrack: warning: {warning}", file=sys.stderr, flush=True)
    quiet_ffmpeg(settings.log_level)  # for the workers, which inherit the fork server's
    start_fork_server()
    # the application (half of the command's imports) only once the settings are known good:
    # a wrong one is then said at once
    import uvicorn

    from service.app import LimitedHttpProtocol, StoppingServer, create_app

    config = uvicorn.Config(
        create_app(settings, data_folder),
        host=settings.host,
        port=settings.port,
        log_config=uvicorn_log_config(settings.log_level),
        log_level=settings.log_level.lower(),
        # request headers' deadline and the connection cap (VTRACK_HEADER_SECONDS,
        # VTRACK_MAX_CONNECTIONS), which uvicorn's own settings do not give
        http=LimitedHttpProtocol.configured(settings),
        timeout_graceful_shutdown=10,
    )
    StoppingServer(config).run(sockets=[listener])
    return 0


def _zenoh_posture(settings: Settings) -> str:
    """One line on who may use the live streams' Zenoh side: open (the default, on loopback),
    or authenticated with the access rules, or whatever the router in front decides."""
    options = settings.zenoh
    security = options.security
    if options.mode == "client":
        return (
            f"Zenoh: a client of {', '.join(options.connect)}; whom it lets in and what they "
            "may do is the router's configuration (`vtrack zenoh router-config` writes one "
            "with this service's rules)"
        )
    where = ", ".join(options.listen)
    if security.access is None:
        return (
            f"Zenoh on {where} is open: no authentication, no access control; any process "
            "that reaches it may publish frames and read tracks (docs/service.md, Security)"
        )
    how = "user/password" if security.users_file is not None else "mutual TLS"
    return (
        f"Zenoh on {where}: a router with {how} authentication and access control; "
        f"{security.access.summary()}"
    )


def _exposure_warnings(settings: Settings, where: str) -> list[str]:
    """What anyone on the network can do with a service listening beyond loopback: the whole
    API without a token, and the Zenoh side always (the token does not cover it; only Zenoh's
    own configuration can)."""
    from service.settings import is_loopback

    warnings = []
    if settings.api_token is None and not is_loopback(settings.host):
        warnings.append(
            f"no VTRACK_API_TOKEN, and the API listens on {where}: anyone who reaches it can "
            "upload, download and delete jobs and stream recordings; set VTRACK_API_TOKEN "
            "(docs/service.md, Security)"
        )
    exposed = settings.zenoh_exposed_endpoints if settings.zenoh_enabled else []
    # only VTRACK_ZENOH_ALLOW_OPEN lets such a service start
    if exposed and not settings.zenoh_security.enforced:
        warnings.append(
            f"Zenoh listens on {', '.join(exposed)} without authentication "
            "(VTRACK_ZENOH_ALLOW_OPEN): anyone who reaches it can read every camera's "
            "frames and tracks, send frames of their own and stop the tracking of a camera "
            "(VTRACK_API_TOKEN does not cover Zenoh); give VTRACK_ZENOH_USERS_FILE or "
            "VTRACK_ZENOH_TLS_CLIENT_AUTH (docs/service.md, Security), or listen on 127.0.0.1"
        )
    return warnings
