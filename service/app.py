"""The ASGI application: ``create_app()`` builds it, the lifespan opens what it owns.

``uvicorn service.app:app`` serves it with every default (settings from ``VTRACK_*``
environment variables). Nothing happens at import: the data folder is claimed (unless
``vtrack serve`` claimed it before it took its port), the job store opens, interrupted jobs are
requeued and the worker processes start in the lifespan, and stop with it.
"""

from __future__ import annotations

import asyncio
import json
import logging
import multiprocessing.util
import shutil
import signal
import threading
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager, contextmanager
from http import HTTPStatus
from types import FrameType
from typing import ClassVar, cast
from urllib.parse import urlsplit

import anyio
import psycopg
import uvicorn
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi_offline import FastAPIOffline
from starlette.exceptions import HTTPException
from starlette.responses import Response
from starlette.routing import Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from api_schemas.common import ERROR_STATUS, ErrorType, error_message
from service import __version__
from service.data_folder import DataFolder, claim_data_folder
from service.delivery.dispatch import Dispatcher
from service.delivery.outbox import Outbox
from service.delivery.setup import make_sinks, sink_names
from service.deps import token_refusal
from service.errors import error_body, error_response, error_type
from service.jobs.files import FolderFiles
from service.jobs.housekeeping import Housekeeper, sweep
from service.jobs.probing import VideoProber
from service.jobs.runner import WorkerConfig
from service.jobs.store import JobStore
from service.jobs.workers import WorkerPool
from service.logs import LOG_FORMAT, quiet_ffmpeg
from service.metrics import make_registry
from service.pipelines import PipelineResources
from service.routers import contract, health, jobs, metrics, streams
from service.settings import Settings, ip_address, is_loopback
from service.storage import storage_problem
from service.streams.manager import StreamManager
from service.streams.store import StreamStore

log = logging.getLogger("service")

DESCRIPTION = """Upload a surveillance video, get back who walked where: one trajectory per
person (box, body parts, confidence, occlusion), as JSON, MCAP (opens in Foxglove), MOTChallenge
text and an annotated MP4. Jobs run in worker processes and survive a restart of the service.

Or track cameras live: frames published on Zenoh in, tracks published back as they are computed
(`/v1/streams`).

Every error answers JSON, an `ErrorResponse`: `type`, a stable code for programs (`ErrorType`
lists them with their statuses), `detail`, a sentence saying what went wrong and what to do, and
for a request that fails its schema (422) `errors`, each failed check. Each operation lists
every status it can answer, those that any request can meet included (a missing token, a
request too slow or too large, too many connections). A method a path does not take is answered
405, with `Allow` naming those it takes.
"""


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings or Settings()
    # `vtrack serve` configured logging already; this serves `uvicorn service.app:app`
    logging.basicConfig(level=settings.log_level.upper(), format=LOG_FORMAT)
    quiet_ffmpeg(settings.log_level)
    # `vtrack serve` claimed the folder already, to refuse a bad one in a line before it serves;
    # under `uvicorn service.app:app` a DataFolderError stops the start-up here, with its reason
    claimed_here = None if app.state.data_folder is not None else claim_data_folder(settings)
    sinks = sink_names(settings)  # the webhooks and the MQTT broker that hear of events
    store = JobStore(settings.job_database, folder=settings.data_dir, sinks=sinks)
    requeued, failed = store.requeue_orphans(settings.max_attempts, settings.instance)
    for job_id in requeued:
        log.warning("job %s queued again: the service died while it ran", job_id)
    for job_id in failed:
        log.warning(
            "job %s failed: the service died while it ran as often as VTRACK_MAX_ATTEMPTS (%d) "
            "allows",
            job_id,
            settings.max_attempts,
        )
    files = FolderFiles(settings.data_dir)
    sweep(settings, store, files, orphans=True)
    config = WorkerConfig(
        database=settings.job_database,
        files=files,
        poll_interval=settings.poll_interval,
        resources=PipelineResources.from_settings(settings),
        log_level=settings.log_level,
        instance=settings.instance,
        lease=settings.job_lease_seconds if store.shared else None,
        sinks=sinks,
    )
    # no worker is replaced once a stop signal came: the service is stopping them
    stopping = app.state.stopping
    pool = WorkerPool(
        store,
        config,
        settings.workers,
        settings.job_timeout,
        settings.job_stall_timeout,
        stop_requested=stopping,
        max_attempts=settings.max_attempts,
    )
    pool.start()
    streams = StreamManager(
        StreamStore(settings.job_database),
        settings.zenoh,
        settings.zenoh_prefix,
        settings.streams_dir,
        config.resources,
        frame_limit=settings.stream_frame_limit,
        log_level=settings.log_level,
        stop_requested=stopping,
        # instances of one database share the streams: spread over them by name
        spread_as=settings.instance if store.shared else None,
        sinks=sinks,
    )
    if settings.zenoh_enabled:
        streams.start(settings.streams)
    else:
        streams.unavailable = "live streams are off (VTRACK_ZENOH_ENABLED=false)"
    app.state.settings = settings
    app.state.prober = VideoProber(log_level=settings.log_level)
    app.state.store = store
    app.state.files = files
    app.state.pool = pool
    app.state.streams = streams
    app.state.registry = make_registry(
        store, pool, streams, settings.data_dir, settings.instance, sinks
    )
    dispatcher = None
    if sinks:
        outbox = Outbox(settings.job_database)
        max_age = settings.events_max_age_hours * 3600
        dispatcher = Dispatcher(outbox, make_sinks(settings), max_age=max_age).start()
    log.info("data in %s; worker processes: %d", settings.data_dir.resolve(), settings.workers)
    housekeeper = Housekeeper(settings, store, files)
    housekeeper.start()
    try:
        yield
    finally:
        housekeeper.stop()
        streams.shutdown()
        pool.stop()
        if dispatcher is not None:  # what it did not send waits in the outbox
            dispatcher.stop()
            dispatcher.outbox.close()
        app.state.prober.close()
        store.close()
        for name in ("pool", "prober", "store", "files", "registry", "streams"):
            delattr(app.state, name)
        if claimed_here is not None:  # only once the workers are gone
            claimed_here.release()


def _log_refusal(request: Request, status: int, detail: object) -> None:
    """Say in the log why a request was refused, as its client was told: the access line
    alone shows a status, and an operator asked why a camera's uploads fail needs the reason."""
    client = request.client.host if request.client else "?"
    log.info(
        "%s %s from %s refused (%d): %s", request.method, request.url.path, client, status, detail
    )


async def _http_error(request: Request, error: Exception) -> Response:
    """The ErrorResponse of an HTTPException (:class:`~service.errors.ApiError` or one of the
    framework's), logged (:func:`_log_refusal`)."""
    assert isinstance(error, HTTPException)
    _log_refusal(request, error.status_code, error.detail)
    body = error_body(error_type(error), error.detail, getattr(error, "errors", None))
    return JSONResponse(body, status_code=error.status_code, headers=error.headers)


async def _database_away(request: Request, error: Exception) -> JSONResponse:
    """503 while the shared job database cannot be reached (a server restarting): the client
    may try again; the service and its jobs go on."""
    detail = (
        "the job database (VTRACK_DATABASE_URL) cannot be reached just now; try again in a "
        "few seconds"
    )
    _log_refusal(request, 503, f"{detail} ({str(error).strip().splitlines()[0]})")
    return error_response(ErrorType.unavailable, detail, headers={"Retry-After": "5"})


async def _validation_error(request: Request, error: Exception) -> JSONResponse:
    """422 with one sentence naming each bad field, and the checks that failed."""
    errors = error.errors() if isinstance(error, RequestValidationError) else []
    problems = [_problem(item) for item in errors]
    listed = [
        {"loc": list(item.get("loc", ())), "msg": error_message(item), "type": item.get("type")}
        for item in errors
    ]
    detail = "invalid request: " + "; ".join(problems)
    _log_refusal(request, 422, detail)
    return error_response(ErrorType.validation_error, detail, errors=listed)


def _problem(item: dict) -> str:
    """One failed check as a phrase; a body that is not JSON says where the parser stopped
    (FastAPI's own words are "body.10: JSON decode error")."""
    loc = item.get("loc", ())
    if item.get("type") == "json_invalid" and len(loc) == 2:
        reason = (item.get("ctx") or {}).get("error", "not JSON")
        return f"the body is not valid JSON: {reason} at character {loc[1]}"
    return f"{'.'.join(str(p) for p in loc)}: {error_message(item)}"


class _LimitedBodies:
    """ASGI middleware: a request body other than a job's upload (which has its own limits,
    ``VTRACK_MAX_UPLOAD_BYTES`` and ``VTRACK_UPLOAD_IDLE_SECONDS``, and is written to disk as
    it comes) is read here, up to :data:`BODY_LIMIT`, before the route sees it; a longer one
    is answered 413, and one that sends nothing for ``VTRACK_BODY_IDLE_SECONDS`` 408 (a client
    that announced a body and stalled held its connection for ever)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        upload = scope.get("method") == "POST" and scope.get("path") == "/v1/jobs"
        if scope["type"] != "http" or upload or scope.get("method") in ("GET", "HEAD"):
            await self.app(scope, receive, send)
            return
        settings: Settings | None = scope["app"].state.settings
        idle = settings.body_idle_seconds if settings is not None else None
        chunks, size = [], 0
        while True:
            with anyio.move_on_after(idle) as waited:
                message = await receive()
            if waited.cancelled_caught:
                detail = (
                    f"nothing of the request body arrived for {idle:g} s "
                    f"(VTRACK_BODY_IDLE_SECONDS) after {size} bytes: send the request again"
                )
                _log_refusal(Request(scope), 408, detail)
                closing = {"Connection": "close"}  # the rest of the body is not read
                response = error_response(ErrorType.timeout, detail, headers=closing)
                await response(scope, receive, send)
                return
            if message["type"] == "http.disconnect":
                # an answer nobody reads, for the middlewares above, which take none for an
                # internal error ("No response returned") and log its traceback
                detail = "the client went away before its request body was complete"
                await error_response(ErrorType.bad_request, detail)(scope, receive, send)
                return
            chunks.append(message.get("body", b""))
            size += len(chunks[-1])
            if size > BODY_LIMIT:
                detail = (
                    f"the request body is over {BODY_LIMIT // 1024} KiB, more than any request "
                    "here but an upload needs"
                )
                _log_refusal(Request(scope), 413, detail)
                response = error_response(ErrorType.payload_too_large, detail)
                await response(scope, receive, send)
                return
            if not message.get("more_body", False):
                break
        body = b"".join(chunks)
        if problem := _not_utf8(scope, body):
            _log_refusal(Request(scope), 422, problem)
            errors = [{"loc": ["body"], "msg": problem, "type": "unicode_decode"}]
            response = error_response(ErrorType.validation_error, problem, errors=errors)
            await response(scope, receive, send)
            return
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if replayed:
                return await receive()  # after the body: the client's disconnect, if it goes
            replayed = True
            return {"type": "http.request", "body": body, "more_body": False}

        await self.app(scope, replay, send)


def _not_utf8(scope: Scope, body: bytes) -> str | None:
    """Why a JSON body cannot be read, when it is not UTF-8 text (FastAPI's own answer is a
    400 "There was an error parsing the body", which says neither what nor how to fix it)."""
    content_type = dict(scope.get("headers") or ()).get(b"content-type", b"")
    if not body or b"json" not in content_type.lower():
        return None
    try:
        body.decode("utf-8")
    except UnicodeDecodeError as error:
        return (
            f"invalid request: the body is not UTF-8 text (byte {error.start} is "
            f"0x{body[error.start]:02x}): send JSON encoded in UTF-8"
        )
    return None


_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


async def _method_not_allowed(request: Request, error: Exception) -> Response:
    """405 naming every method the path takes, in ``Allow`` and in the sentence: Starlette's
    answer lists only the methods of the first route whose path matched, one of several
    when a path has a route per method (``GET`` and ``POST /v1/jobs``)."""
    # each method asked of the router as a request of it would be (routers included in the
    # app keep their routes to themselves)
    allowed = [
        method
        for method in _METHODS
        if any(
            route.matches({**request.scope, "method": method})[0] is Match.FULL
            for route in request.app.routes
        )
    ]
    methods = ", ".join(allowed)
    detail = f"{request.method} is not allowed on {request.url.path}: use {methods}"
    _log_refusal(request, 405, detail)
    return error_response(ErrorType.method_not_allowed, detail, headers={"Allow": methods})


class _InternalErrorsAsJson:
    """ASGI middleware: an exception no route expected answers 500 with an ErrorResponse
    like every other error, and is logged once, with its traceback and the request; one of the
    data folder (full, or not writable: :func:`~service.storage.storage_problem`) answers 507
    saying so, as an upload it refuses is answered, logged as a warning in one line.

    Not an exception handler for ``Exception``: Starlette's error middleware, which runs those,
    raises the exception on after the handler's answer, and uvicorn then logs it a second time
    and drops the connection at once, resetting it under a client still sending its upload.
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def watched(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, watched)
        except Exception as error:
            if started:  # too late for an answer: the server logs it and drops the connection
                raise
            if problem := storage_problem(error):  # the data folder's, not the request's
                detail = f"{problem.problem}: {problem.remedy}"
                log.warning("%s %s refused (507): %s", scope["method"], scope["path"], detail)
                response = error_response(ErrorType.insufficient_storage, detail)
                await response(scope, receive, send)
                return
            log.exception("internal error answering %s %s", scope["method"], scope["path"])
            detail = (
                f"internal error ({type(error).__name__}) while answering {scope['method']} "
                f"{scope['path']}: the service's log has the details; tell its operator"
            )
            await error_response(ErrorType.internal, detail)(scope, receive, send)


DOCS_ASSETS = "/docs-assets"
"""Where the API docs' JavaScript, CSS and icon are served: generic files, open without the
token (the schema they render, ``/openapi.json``, is not)."""

OPEN_PATHS = frozenset({"/healthz", "/readyz"})
"""What answers without the token: the probes of orchestrators and load balancers."""

BODY_LIMIT = 64 * 1024
"""Most bytes of a request body other than an upload's (a stream's settings are a few hundred)."""


def _site_refusal(settings: Settings, method: str, host: str, origin: str | None) -> str | None:
    """Why a browser's request must not reach the API, or None. A web page of another site
    may post a form to it (browsers send such a POST without asking), and one whose own name
    its author points at 127.0.0.1 (DNS rebinding) may read the answers too: a service on
    loopback answers only to IP addresses, ``localhost`` and ``VTRACK_ALLOWED_HOSTS``, and a
    request that changes something from a page of another site (its ``Origin``) is refused.
    Programs send no ``Origin``."""
    name = urlsplit(f"//{host}").hostname or ""
    if (
        name
        and is_loopback(settings.host)
        and not (name in ("localhost", *settings.allowed_hosts) or name.endswith(".localhost"))
        and ip_address(name) is None
    ):
        return (
            f"this service listens on {settings.host} and answers to its addresses and "
            f"localhost, not to the name {name!r}: a proxy in front that passes that name "
            "needs it in VTRACK_ALLOWED_HOSTS"
        )
    changes = method not in ("GET", "HEAD", "OPTIONS")
    if changes and origin is not None and urlsplit(origin).netloc != host:
        return (
            f"a request from a web page of {origin} may not change anything here (cross-site): "
            "send it from a program, or from this service's own pages"
        )
    return None


async def _refusals_before_anything_else(request: Request, call_next):
    """Before anything of the request is read: :func:`_site_refusal` (403), then, with
    ``VTRACK_API_TOKEN`` set, the token on every path but :data:`OPEN_PATHS` and the
    documentation's generic files (401). FastAPI reads and parses a JSON body before a route's
    dependencies run, so the routers' token dependency (kept for the OpenAPI security scheme)
    comes too late for a gigabyte of JSON; and FastAPI serves the documentation outside the
    routers. One middleware: each of Starlette's re-raises an exception from the app, which
    the log would show once per middleware."""
    settings: Settings | None = request.app.state.settings
    if settings is None:
        return await call_next(request)
    headers = request.headers
    refusal = _site_refusal(
        settings, request.method, headers.get("host", ""), headers.get("origin")
    )
    if refusal is not None:
        _log_refusal(request, 403, refusal)
        return error_response(ErrorType.forbidden, refusal)
    path = request.url.path
    if not (path in OPEN_PATHS or path.startswith(DOCS_ASSETS + "/")):
        refusal = token_refusal(settings, headers.get("authorization"))
        if refusal is not None:
            _log_refusal(request, 401, refusal)
            return error_response(
                ErrorType.unauthorized, refusal, headers={"WWW-Authenticate": "Bearer"}
            )
    return await call_next(request)


def create_app(settings: Settings | None = None, data_folder: DataFolder | None = None) -> FastAPI:
    """The application; ``settings`` default to the environment, read when it starts.

    ``data_folder``: the settings' data folder, claimed already by the caller, who keeps it as
    long as the app runs; without it, the lifespan claims the folder itself.
    """
    # The docs pages load Swagger UI and ReDoc from the service (DOCS_ASSETS), not from a CDN:
    # cameras often sit on networks without internet access.
    app = FastAPIOffline(
        static_url=DOCS_ASSETS,
        title="visual-tracking",
        version=__version__,
        summary="Multi-person tracking of uploaded surveillance video",
        description=DESCRIPTION,
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.data_folder = data_folder
    # Set by `vtrack serve` when a stop signal comes: open event streams end at once instead of
    # holding the stop for the graceful-shutdown timeout (their clients reconnect elsewhere).
    app.state.stopping = threading.Event()
    app.state.event_streams = 0  # clients following job events now (VTRACK_MAX_EVENT_STREAMS)
    app.add_exception_handler(405, _method_not_allowed)
    app.add_exception_handler(HTTPException, _http_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(psycopg.OperationalError, _database_away)
    app.add_middleware(_LimitedBodies)
    app.middleware("http")(_refusals_before_anything_else)  # outside the limit: first
    app.add_middleware(_InternalErrorsAsJson)  # added last: outside the others, to catch theirs
    app.include_router(health.router)
    app.include_router(jobs.router)
    app.include_router(streams.router)
    app.include_router(metrics.router)
    contract.install(app)  # every status each operation can answer, in /openapi.json
    return app


MAX_HEADER_BYTES = 64 * 1024
"""Most bytes of a request's line and headers (a browser's, cookies and all, are a few KiB)."""


class LimitedHttpProtocol(HttpToolsProtocol):
    """uvicorn's HTTP/1.1 protocol (httptools, which ``uvicorn[standard]`` brings) with the
    limits uvicorn has no setting for: it times out only a kept-alive connection idle between
    requests (``timeout_keep_alive``), and its connection cap (``limit_concurrency``) answers
    in plain text.

    - a request's line and headers must arrive within :attr:`header_seconds` of the
      connection's opening (on a kept-alive connection, of the request's first byte), and in
      at most :data:`MAX_HEADER_BYTES`, else the connection is closed with 408 or 431 (without
      an answer when nothing came): a client that sends them a byte at a time, or connects
      and sends nothing, held its connection for ever;
    - a request on a connection beyond :attr:`max_connections` gets 503 (JSON, like every
      error of the service, with ``Retry-After``) and its connection is closed.

    ``vtrack serve`` gives uvicorn a subclass with the settings' values (:meth:`configured`);
    ``uvicorn service.app:app --http service.app:LimitedHttpProtocol`` runs these defaults.
    """

    header_seconds: ClassVar[float] = Settings.model_fields["header_seconds"].default
    max_connections: ClassVar[int] = Settings.model_fields["max_connections"].default

    @classmethod
    def configured(cls, settings: Settings) -> type[LimitedHttpProtocol]:
        """This protocol with ``VTRACK_HEADER_SECONDS`` and ``VTRACK_MAX_CONNECTIONS``."""
        limits = {
            "header_seconds": settings.header_seconds,
            "max_connections": settings.max_connections,
        }
        return type(cls.__name__, (cls,), limits)

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._header_timer: asyncio.TimerHandle | None = None
        self._header_bytes = 0
        self._await_headers()

    def connection_lost(self, exc: Exception | None) -> None:
        self._headers_arrived()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        super().data_received(data)  # parses: the headers' end stops the timer
        if self._header_timer is None or self.transport.is_closing():
            return
        self._header_bytes += len(data)  # all of it before the headers' end
        if self._header_bytes > MAX_HEADER_BYTES:
            self._headers_arrived()
            self._close(
                ErrorType.headers_too_large,
                f"the request's line and headers are over {MAX_HEADER_BYTES // 1024} KiB",
            )

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._await_headers()  # a later request on the connection: its deadline starts now

    def on_headers_complete(self) -> None:
        self._headers_arrived()
        if len(self.connections) <= self.max_connections:
            super().on_headers_complete()
            return
        # uvicorn starts the request's ASGI task with self.app: this one answers 503
        app, self.app = self.app, _too_many_connections
        try:
            super().on_headers_complete()
        finally:
            self.app = app

    def _await_headers(self) -> None:
        if self._header_timer is None:
            self._header_bytes = 0
            self._header_timer = self.loop.call_later(self.header_seconds, self._headers_late)

    def _headers_arrived(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _headers_late(self) -> None:
        self._header_timer = None
        if self.transport.is_closing():
            return
        if not self._header_bytes:  # a connection opened and left silent: nothing to answer
            self.transport.close()
            return
        self._close(
            ErrorType.timeout,
            f"the request's headers did not arrive within {self.header_seconds:g} s "
            "(VTRACK_HEADER_SECONDS)",
        )

    def _close(self, type: ErrorType, detail: str) -> None:
        """Answer an ErrorResponse of ``type`` and close the connection."""
        status = ERROR_STATUS[type]
        client = self.client[0] if self.client else "?"
        log.info("connection from %s closed (%d): %s", client, status, detail)
        body = json.dumps(error_body(type, detail)).encode()
        head = (
            f"HTTP/1.1 {status} {HTTPStatus(status).phrase}\r\n"
            f"content-type: application/json\r\ncontent-length: {len(body)}\r\n"
            "connection: close\r\n\r\n"
        )
        self.transport.write(head.encode() + body)
        self.transport.close()


async def _too_many_connections(scope: Scope, receive: Receive, send: Send) -> None:
    """The answer to a request on a connection beyond ``VTRACK_MAX_CONNECTIONS``."""
    detail = (
        "the service has as many connections open as it serves at once "
        "(VTRACK_MAX_CONNECTIONS): try again in a moment"
    )
    _log_refusal(Request(scope), 503, detail)
    headers = {"Retry-After": "1", "Connection": "close"}
    await error_response(ErrorType.busy, detail, headers=headers)(scope, receive, send)


class StoppingServer(uvicorn.Server):
    """uvicorn's server, telling the app when a stop signal comes (``app.state.stopping``) so
    that its event streams end and the stop does not wait out the graceful-shutdown timeout;
    and removing multiprocessing's temporary folder when SIGTERM stops it.

    uvicorn ends a graceful stop by raising the stop signal again, with its default action:
    SIGTERM's kills the process without running ``atexit``, where multiprocessing removes its
    ``pymp-*`` folder (the fork server's socket) from the system's temporary folder, so every
    start and stop by a service manager left one there. (Ctrl-C ends in a KeyboardInterrupt,
    which runs ``atexit``.)
    """

    _terminated = False

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        cast(FastAPI, self.config.app).state.stopping.set()  # create_app's (`vtrack serve`)
        self._terminated = self._terminated or sig == signal.SIGTERM
        super().handle_exit(sig, frame)

    @contextmanager
    def capture_signals(self) -> Iterator[None]:
        with super().capture_signals():  # raises the signal again as it ends
            try:
                yield
            finally:
                if self._terminated:  # the workers are gone: the fork server takes no more
                    shutil.rmtree(multiprocessing.util.get_temp_dir(), ignore_errors=True)


app = create_app()
