"""File downloads (results, recordings) that answer like the rest of the API.

Starlette's :class:`FileResponse` serves ranges, which players need to seek, but answers a bad
``Range`` header in plain text (an empty body for 416) and ignores ``If-None-Match``.
:class:`Download` keeps its file serving and changes only those two answers.
"""

from __future__ import annotations

import json
import os
from typing import Any

import anyio
from fastapi.responses import FileResponse
from starlette.datastructures import Headers
from starlette.types import Message, Receive, Scope, Send

from api_schemas.common import ErrorType
from service.errors import error_body

__all__ = ["NOT_MODIFIED", "RANGE_ERRORS", "Download", "accepts_gzip"]

RANGE_ERRORS = {
    400: "A Range header that cannot be served.",
    416: "A Range that starts beyond the end of the file.",
}
"""Descriptions of a download's range errors, for the route's OpenAPI ``responses``."""
NOT_MODIFIED: dict[int | str, dict[str, Any]] = {
    304: {"description": "If-None-Match named the file's ETag: the client has this copy."}
}
"""The OpenAPI ``responses`` entry of a download's ``304``."""


def accepts_gzip(accept_encoding: str | None) -> bool:
    """Whether an ``Accept-Encoding`` header takes gzip (RFC 9110 12.5.3): listed, or ``*``,
    with a weight above 0 (``gzip;q=0`` refuses it)."""
    weights = {}
    for item in (accept_encoding or "").split(","):
        coding, *params = (part.strip().lower() for part in item.split(";"))
        weight = 1.0
        for param in params:
            name, _, value = param.partition("=")
            if name.strip() == "q":
                try:
                    weight = float(value)
                except ValueError:
                    weight = 0.0
        weights[coding] = weight
    for coding in ("gzip", "x-gzip", "*"):
        if coding in weights:
            return weights[coding] > 0
    return False


def _matches(if_none_match: str, etag: str) -> bool:
    """RFC 9110 13.1.2: ``*`` or any listed tag, compared weakly (``W/`` ignored)."""
    tags = [tag.strip().removeprefix("W/") for tag in if_none_match.split(",")]
    return "*" in tags or etag.removeprefix("W/") in tags


class Download(FileResponse):
    """A file download: ranges as :class:`FileResponse` serves them, range errors as an
    ErrorResponse, and ``304 Not Modified`` to a client that has the file (its ETag)."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if self.stat_result is None:  # the ETag and a 416's size come from it
            self.stat_result = await anyio.to_thread.run_sync(os.stat, self.path)
            self.set_stat_headers(self.stat_result)
        headers = Headers(scope=scope)
        if_none_match = headers.get("if-none-match")
        if (
            if_none_match is not None
            and scope["method"] in ("GET", "HEAD")
            and _matches(if_none_match, self.headers["etag"])
        ):
            names = ("etag", "last-modified", "cache-control", "vary")
            kept = [(k, self.headers.get(k)) for k in names]
            await send({
                "type": "http.response.start",
                "status": 304,
                "headers": [(k.encode(), v.encode()) for k, v in kept if v],
            })  # fmt: skip
            await send({"type": "http.response.body", "body": b""})
            return
        requested = headers.get("range")
        if requested is not None and requested.partition("=")[0].strip().lower() != "bytes":
            # a range unit other than bytes: ignored, the whole file is sent (RFC 9110 14.2)
            kept = [(k, v) for k, v in scope["headers"] if k.lower() != b"range"]
            scope = {**scope, "headers": kept}
        await super().__call__(scope, receive, self._json_range_errors(headers, send))

    def _json_range_errors(self, headers: Headers, send: Send) -> Send:
        """``send`` with the plain-text 400/416 answers to a bad Range header made JSON (a
        200 or 206 passes untouched: the file was served)."""
        error: dict[str, Any] = {}

        async def sending(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] in (400, 416):
                error.update(message)
                return
            if not error:
                await send(message)
                return
            requested = headers.get("range", "")
            if error["status"] == 416:
                assert self.stat_result is not None  # stat in __call__, before the file
                size = self.stat_result.st_size
                detail = (
                    f"Range {requested!r} starts beyond the end of the file ({size} bytes; "
                    "Content-Range gives the size)"
                )
            else:
                text = message.get("body", b"").decode(errors="replace")
                reason = text.removeprefix("Range header: ").strip(" .")
                if reason == "range must be requested":  # Starlette's words for no range found
                    reason = "no range in it"
                detail = (
                    f"Range {requested!r} cannot be served ({reason or 'malformed'}): ask for "
                    "bytes=START-END, bytes=START- or bytes=-LENGTH"
                )
            kind = (
                ErrorType.range_not_satisfiable
                if error["status"] == 416
                else ErrorType.invalid_range
            )
            body = json.dumps(error_body(kind, detail)).encode()
            kept = [
                (k, v)
                for k, v in error["headers"]
                if k.lower() not in (b"content-type", b"content-length")
            ]
            await send({
                "type": "http.response.start",
                "status": error["status"],
                "headers": [*kept, (b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode())],
            })  # fmt: skip
            await send({"type": "http.response.body", "body": body})

        return sending
