"""Receiving an upload: the multipart body streamed straight to disk, under a size limit.

``POST /v1/jobs`` takes ``multipart/form-data`` with a ``video`` file part and an optional
``options`` part (JSON). The body is parsed as it arrives: video bytes go to a file in chunks
(never the whole file in memory), the limit is enforced while receiving (and up front from
``Content-Length``), and anything else in the body is an error that says what was expected.
"""

from __future__ import annotations

import contextlib
import logging
import re
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

import anyio
from fastapi import Request
from python_multipart import MultipartParser
from python_multipart.exceptions import FormParserError
from python_multipart.multipart import parse_options_header
from starlette.requests import ClientDisconnect

from api_schemas.common import ErrorType
from service.errors import ApiError
from service.storage import storage_problem

if TYPE_CHECKING:
    from python_multipart.multipart import MultipartCallbacks

log = logging.getLogger(__name__)

VIDEO_PART = "video"
OPTIONS_PART = "options"
MAX_OPTIONS_BYTES = 64 * 1024
_ENVELOPE_BYTES = MAX_OPTIONS_BYTES + 16 * 1024
"""Room for part headers, boundaries and the options part beside the video itself."""
_DRAIN_BYTES = 64 * 1024 * 1024
"""After a too-large upload, read (and drop) at most this much more, so that the client
sees the 413 answer rather than a reset connection."""
_DRAIN_IDLE_SECONDS = 5.0
"""A refused body is drained only while it keeps coming: a pause this long (or the upload's
idle timeout, if shorter) ends the draining, and the answer goes. Before, a client that
announced gigabytes and sent nothing held its connection, unanswered, for ever."""


_FORM_ESCAPES = {"%22": '"', "%0D": "\r", "%0A": "\n"}
"""What browsers and curl write for the characters a form's file name cannot hold (HTML's
multipart/form-data encoding), and only those: any other ``%`` is the name's own."""


_CONTROL_CHARACTERS = re.compile(r"[\x00-\x1f\x7f-\x9f]")
"""Unicode's control characters (C0, DEL, C1): no file name needs one, and a name is shown
in results, the log and terminals, where a newline forges a line and an escape sequence
rewrites the screen."""


def _client_filename(raw: bytes) -> str | None:
    """The client's file name, without folders or control characters, from a form part's
    ``filename``; None when nothing is left."""
    name = Path(raw.decode("utf-8", "replace")).name
    name = re.sub("|".join(_FORM_ESCAPES), lambda m: _FORM_ESCAPES[m[0].upper()], name, flags=re.I)
    return _CONTROL_CHARACTERS.sub("", name) or None


class UploadError(Exception):
    """Why the body being parsed is refused, raised from the parser's callbacks."""

    def __init__(self, type: ErrorType, detail: str) -> None:
        super().__init__(detail)
        self.type = type
        self.detail = detail


@dataclass(slots=True)
class ReceivedUpload:
    video_path: Path
    filename: str | None
    size: int
    options: bytes | None


class _Receiver:
    """python-multipart callbacks that route the parts of one upload."""

    def __init__(self, video_path: Path, max_bytes: int) -> None:
        self.video_path = video_path
        self.max_bytes = max_bytes
        self.size = 0
        self.filename: str | None = None
        self.options: bytearray | None = None
        self.seen: set[str] = set()
        self._file: BinaryIO | None = None
        self._pending: list[bytes] = []
        self._part: str | None = None
        self._header_name = b""
        self._header_value = b""
        self._disposition: bytes | None = None
        self._part_type: bytes | None = None

    def callbacks(self) -> MultipartCallbacks:
        return {
            "on_part_begin": self._on_part_begin,
            "on_header_field": self._on_header_field,
            "on_header_value": self._on_header_value,
            "on_header_end": self._on_header_end,
            "on_headers_finished": self._on_headers_finished,
            "on_part_data": self._on_part_data,
            "on_part_end": self._on_part_end,
        }

    def _on_part_begin(self) -> None:
        self._part = None
        self._disposition = None
        self._part_type = None

    def _on_header_field(self, data: bytes, start: int, end: int) -> None:
        self._header_name += data[start:end]

    def _on_header_value(self, data: bytes, start: int, end: int) -> None:
        self._header_value += data[start:end]

    def _on_header_end(self) -> None:
        if self._header_name.lower() == b"content-disposition":
            self._disposition = self._header_value
        elif self._header_name.lower() == b"content-type":
            self._part_type = self._header_value
        self._header_name = self._header_value = b""

    def _on_headers_finished(self) -> None:
        _, params = parse_options_header(self._disposition or b"")
        name = params.get(b"name", b"").decode("utf-8", "replace")
        if name not in (VIDEO_PART, OPTIONS_PART):
            raise UploadError(
                ErrorType.invalid_upload,
                f"unexpected form part {name!r}: send the video as the {VIDEO_PART!r} file part "
                f"and, optionally, the job options as the {OPTIONS_PART!r} part (JSON)",
            )
        if name in self.seen:
            raise UploadError(
                ErrorType.invalid_upload, f"the {name!r} part was sent twice; send it once"
            )
        self.seen.add(name)
        self._part = name
        if name == VIDEO_PART:
            raw = params.get(b"filename")
            if raw is None and self._part_type is None:
                # what a form's text field looks like: curl -F video=clip.mp4 (without the @)
                raise UploadError(
                    ErrorType.invalid_upload,
                    f"the {VIDEO_PART!r} part is a text field, not a file (it has neither a "
                    "file name nor a content type): send the file itself, e.g. with curl "
                    f"-F {VIDEO_PART}=@clip.mp4 (the @ makes curl send the file's bytes)",
                )
            self.filename = _client_filename(raw) if raw else None
            self._file = self.video_path.open("wb")
        else:
            self.options = bytearray()

    def _on_part_data(self, data: bytes, start: int, end: int) -> None:
        chunk = data[start:end]
        if self._part == VIDEO_PART:
            self.size += len(chunk)
            if self.size > self.max_bytes:
                raise UploadError(ErrorType.payload_too_large, too_large(self.max_bytes))
            self._pending.append(chunk)
        elif self.options is not None:
            if len(self.options) + len(chunk) > MAX_OPTIONS_BYTES:
                raise UploadError(
                    ErrorType.payload_too_large,
                    f"the options part is larger than {MAX_OPTIONS_BYTES} bytes",
                )
            self.options.extend(chunk)

    def _on_part_end(self) -> None:
        self._part = None

    def flush(self) -> None:
        """Write the video bytes received so far (called in a worker thread)."""
        if self._file is not None and self._pending:
            self._file.write(b"".join(self._pending))
        self._pending.clear()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


def too_large(max_bytes: int) -> str:
    return (
        f"the video is larger than this service accepts ({max_bytes} bytes, "
        "VTRACK_MAX_UPLOAD_BYTES): send a shorter or more compressed video"
    )


async def receive_upload(
    request: Request, video_path: Path, max_bytes: int, idle_seconds: float
) -> ReceivedUpload:
    """Stream the request's multipart body; the video part goes to ``video_path``.

    Raises
    ------
    ApiError
        408 when nothing of the body arrives for ``idle_seconds`` (a stalled client would
        otherwise hold its connection and its partial file for ever), 413 above the size
        limit, 415 for a body that is not multipart, 422 for a missing ``video`` part, an
        unexpected part or a malformed body, 507 when the data folder cannot take the video
        (disk full, file-size limit).
    """
    content_type = request.headers.get("content-type", "")
    kind, params = parse_options_header(content_type)
    if kind != b"multipart/form-data" or b"boundary" not in params:
        raise ApiError(
            ErrorType.unsupported_media,
            "send the upload as multipart/form-data with the video in a 'video' file part "
            f"(got Content-Type {content_type or 'none'!r})",
        )
    declared = request.headers.get("content-length")
    drain_idle = min(idle_seconds, _DRAIN_IDLE_SECONDS)
    if declared and declared.isdigit() and int(declared) > max_bytes + _ENVELOPE_BYTES:
        await _drain(request.stream(), drain_idle)
        raise ApiError(ErrorType.payload_too_large, too_large(max_bytes))
    receiver = _Receiver(video_path, max_bytes)
    parser = MultipartParser(params[b"boundary"], receiver.callbacks())
    received = 0
    chunks = request.stream()
    try:
        while True:
            with anyio.move_on_after(idle_seconds) as waited:
                chunk = await anext(chunks, None)
            if waited.cancelled_caught:
                raise UploadError(
                    ErrorType.timeout,
                    f"nothing of the upload arrived for {idle_seconds:g} s "
                    f"(VTRACK_UPLOAD_IDLE_SECONDS) after {received} bytes; nothing was kept: "
                    "send it again",
                )
            if chunk is None:
                break
            received += len(chunk)
            parser.write(chunk)
            await anyio.to_thread.run_sync(receiver.flush)
        parser.finalize()
        receiver.close()  # inside: the last buffered bytes may not fit either
    except UploadError as error:
        receiver.close()
        video_path.unlink(missing_ok=True)
        if error.type == ErrorType.payload_too_large:
            await _drain(chunks, drain_idle)
        raise ApiError(error.type, error.detail) from None
    except FormParserError as error:
        receiver.close()
        video_path.unlink(missing_ok=True)
        raise ApiError(
            ErrorType.invalid_upload,
            f"the multipart body is malformed ({error}); send multipart/form-data with a "
            "'video' file part",
        ) from None
    except OSError as error:
        problem = storage_problem(error)
        with contextlib.suppress(OSError):  # closing flushes, and may fail the same way
            receiver.close()
        video_path.unlink(missing_ok=True)
        if problem is None:
            raise
        await _drain(chunks, drain_idle)
        raise ApiError(
            ErrorType.insufficient_storage,
            f"{problem.problem}: the upload was not kept; {problem.remedy}, then send the video "
            "again",
        ) from None
    except ClientDisconnect:
        # the client gave up mid-upload: nothing was kept, nobody reads an answer, and it is
        # the client's doing, so one log line rather than the server error's traceback
        receiver.close()
        video_path.unlink(missing_ok=True)
        log.warning("upload abandoned by the client after %d bytes; nothing kept", received)
        raise ApiError(
            ErrorType.bad_request, "the client disconnected before the upload was complete"
        ) from None
    except BaseException:
        receiver.close()
        video_path.unlink(missing_ok=True)
        raise
    if VIDEO_PART not in receiver.seen:
        video_path.unlink(missing_ok=True)
        raise ApiError(
            ErrorType.invalid_upload,
            "the upload has no 'video' part: send the video file as the multipart file part "
            "named 'video'",
        )
    options = bytes(receiver.options) if receiver.options is not None else None
    return ReceivedUpload(video_path, receiver.filename, receiver.size, options)


async def _drain(chunks: AsyncIterator[bytes], idle_seconds: float) -> None:
    """Read and drop what is left of a refused body (at most :data:`_DRAIN_BYTES`), until it
    pauses for ``idle_seconds``."""
    drained = 0
    try:
        while drained <= _DRAIN_BYTES:
            with anyio.move_on_after(idle_seconds) as waited:
                chunk = await anext(chunks, None)
            if waited.cancelled_caught:
                log.debug(
                    "a refused upload paused for %g s: answered without its rest", idle_seconds
                )
                return
            if chunk is None:
                return
            drained += len(chunk)
    except Exception:
        log.debug("client went away while its too-large upload was drained")
