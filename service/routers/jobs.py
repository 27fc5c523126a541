"""``/v1/jobs``: upload a video as a job, follow it, fetch its results, cancel or delete it."""

from __future__ import annotations

import asyncio
import logging
import re
import threading
import time
from typing import Annotated
from urllib.parse import urlencode

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import StreamingResponse
from pydantic import AwareDatetime, BeforeValidator

from api_schemas.analytics import AnalyticsResult, EventType
from api_schemas.common import ErrorType
from api_schemas.jobs import (
    JobCreated,
    JobList,
    JobOptions,
    JobState,
    JobStatus,
    OutputFormat,
    ProgressEvent,
)
from api_schemas.tracks import Trajectories
from service.analysis import ANALYTICS_FILE
from service.deps import AuthDep, FilesDep, KnownQueryDep, SettingsDep, StoreDep
from service.errors import ApiError, options_error
from service.jobs.housekeeping import remove_job
from service.jobs.store import JobRecord, JobStore
from service.jobs.submit import SubmitError, new_job_id, submit
from service.jobs.views import API_PREFIX, events_url, job_status, progress_event, status_url
from service.outputs.base import MEDIA_TYPES
from service.pipelines import OptionsError
from service.routers import BINARY_CONTENT, error_responses
from service.routers.contract import schema_ref
from service.routers.downloads import NOT_MODIFIED, RANGE_ERRORS, Download, accepts_gzip
from service.uploads import receive_upload

log = logging.getLogger(__name__)

router = APIRouter(prefix="/v1/jobs", tags=["jobs"], dependencies=[AuthDep, KnownQueryDep])

_RESULT_CONTENT = {
    "description": "The result file: `json` a Trajectories document, `mot` MOTChallenge text, "
    "`mcap` an MCAP file (Foxglove), `mp4` the annotated video.",
    "model": Trajectories,  # the JSON result's schema, in the components for client generators
    "content": {
        MEDIA_TYPES[OutputFormat.mcap]: BINARY_CONTENT,
        MEDIA_TYPES[OutputFormat.mot]: {"schema": {"type": "string"}},
        MEDIA_TYPES[OutputFormat.mp4]: BINARY_CONTENT,
    },
}

_UPLOAD_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["video"],
                    "additionalProperties": False,  # another part is refused (422)
                    "properties": {
                        "video": {
                            "type": "string",
                            "format": "binary",
                            "description": "The video file (MP4, AVI, MKV...).",
                        },
                        "options": {
                            # what is accepted, the rules across options included (a job's
                            # status shows its options as accepted, by the rules of then)
                            "$ref": schema_ref(JobOptions),
                            "description": "Job options as JSON (optional).",
                        },
                    },
                },
                "encoding": {"options": {"contentType": "application/json"}},
            }
        },
    }
}

NO_SUCH_JOB = {404: "No such job: it never existed or was deleted."}
_TOO_MANY_FOLLOWERS = (
    "As many clients follow job events as the service serves (VTRACK_MAX_EVENT_STREAMS): poll "
    "the job instead, or try again after Retry-After seconds."
)

_UPLOAD_ERRORS = {
    413: "The upload is over VTRACK_MAX_UPLOAD_BYTES (or its options part over 64 KiB); "
    "nothing was kept.",
    415: "Not multipart/form-data, or a video part that is empty or not a video this service "
    "can decode.",
    422: "Options the schema refuses (`errors` lists each failed check, located under "
    "`options`), options this service cannot run on this video (a model it lacks, a first_box "
    "outside the frame, frames too small...), a missing `video` part or a part sent twice, a "
    "malformed multipart body.",
    503: "The service is stopping: send the video again once it is back.",
    507: "The data folder's disk is full or cannot be written: nothing was kept.",
}

_EVENT = {
    "type": "object",
    "required": ["event", "data"],
    "properties": {
        "event": {"enum": ["progress", "end"]},
        "data": {
            "type": "string",
            "contentMediaType": "application/json",
            "contentSchema": {
                "anyOf": [
                    {"$ref": schema_ref(ProgressEvent, "serialization")},
                    {
                        "type": "object",
                        "required": ["id", "deleted"],
                        "properties": {"id": {"type": "string"}, "deleted": {"const": True}},
                    },
                ]
            },
        },
    },
}
"""One server-sent event of a job's stream, as schemathesis and OpenAPI 3.2's ``itemSchema``
read it (fields by name, ``data`` a JSON document)."""

EVENT_POLL_SECONDS = 0.25
KEEPALIVE_SECONDS = 15.0


def _job(store: JobStore, job_id: str) -> JobRecord:
    record = store.get(job_id)
    if record is None:
        raise ApiError(
            ErrorType.not_found,
            f"no job {job_id!r}: it never existed or was deleted (GET /v1/jobs lists the jobs)",
        )
    return record


@router.post(
    "",
    status_code=status.HTTP_202_ACCEPTED,
    summary="Upload a video as a tracking job",
    description="multipart/form-data: the video as the `video` file part, and optionally the "
    "job options (JobOptions, JSON) as the `options` part. The upload streams to disk; the "
    "answer says where to poll.",
    responses=error_responses(*_UPLOAD_ERRORS, why=_UPLOAD_ERRORS),
    openapi_extra=_UPLOAD_BODY,
)
async def create_job(
    request: Request, response: Response, settings: SettingsDep, store: StoreDep, files: FilesDep
) -> JobCreated:
    job_id = new_job_id()
    upload = await receive_upload(
        request, files.receiving(job_id), settings.max_upload_bytes, settings.upload_idle_seconds
    )
    prober = request.app.state.prober
    try:
        record = await submit(job_id, upload, settings, store, files, prober)
    except SubmitError as error:
        raise ApiError(error.type, error.detail, errors=error.errors) from None
    except OptionsError as error:
        raise options_error(error, "options") from None
    response.headers["Location"] = status_url(record.id)
    return JobCreated(
        id=record.id,
        state=record.state,
        status_url=status_url(record.id),
        events_url=events_url(record.id),
    )


_RFC3339 = re.compile(
    r"\d{4}-\d{2}-\d{2}[Tt]\d{2}:\d{2}:\d{2}(?:\.\d+)?(?:[Zz]|[+-]\d{2}:\d{2})", re.ASCII
)
"""A date-time with its offset, as RFC 3339 (and JSON Schema's ``date-time``) writes it."""


def _plus_restored(value: object) -> object:
    """A time written into a URL by hand (``...T08:00:00+01:00``) comes with its ``+`` read as
    a space, as query strings encode spaces: an offset after a space is taken as written."""
    if isinstance(value, str) and re.search(r" \d{2}(:?\d{2})?$", value):
        return value[: value.rindex(" ")] + "+" + value[value.rindex(" ") + 1 :]
    return value


def _rfc3339(value: object) -> object:
    """Only what the parameter's schema says, a ``date-time``: pydantic also reads a number as
    a Unix time (and one over 2e10 as milliseconds), a time without seconds, a space for the
    ``T``; a client that sent those would get jobs of another time than it meant."""
    if isinstance(value, str) and not _RFC3339.fullmatch(value):
        number = re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", value.strip())
        raise ValueError(
            "must be a date-time with its timezone offset, as RFC 3339 writes it "
            "(2026-11-26T08:00:00Z, 2026-11-26T09:00:00+01:00)"
            + (": a number is not read as a Unix time" if number else "")
        )
    return value


@router.get(
    "",
    summary="Jobs, newest first, a page at a time",
    responses=error_responses(
        404, why={404: "No job `before` to page from: it was deleted since the previous page."}
    ),
)
def list_jobs(
    store: StoreDep,
    state: Annotated[JobState | None, Query(description="Only jobs in this state.")] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="Jobs per page.")] = 100,
    before: Annotated[
        str | None, Query(description="Only jobs older than this one: the `next` link's cursor.")
    ] = None,
    finished_after: Annotated[
        Annotated[AwareDatetime, BeforeValidator(_rfc3339), BeforeValidator(_plus_restored)] | None,
        Query(
            description="Only jobs that finished after this time: a date-time with its timezone "
            "offset (RFC 3339, e.g. 2026-11-26T08:00:00Z; a + typed into the URL unencoded, "
            "which reads as a space, is taken as the +): to take in new results, ask again "
            "from a little before the previous ask and skip the ids you have."
        ),
    ] = None,
) -> JobList:
    after = None if finished_after is None else finished_after.timestamp()
    try:
        records = store.list(limit=limit + 1, state=state, before=before, finished_after=after)
    except KeyError:
        raise ApiError(
            ErrorType.not_found,
            f"no job {before!r} to page from: it was deleted since the previous page; start "
            "again from the newest (GET /v1/jobs)",
        ) from None
    page = records[:limit]
    following = None
    if len(records) > limit:
        query = {"limit": limit, "before": page[-1].id} | ({"state": state.value} if state else {})
        if finished_after is not None:
            query["finished_after"] = finished_after.isoformat()
        following = f"{API_PREFIX}?{urlencode(query)}"
    places = store.queue_positions() if any(r.state == JobState.queued for r in page) else {}
    return JobList(jobs=[job_status(r, places.get(r.id)) for r in page], next=following)


@router.get(
    "/{job_id}",
    summary="A job's state and progress",
    responses=error_responses(404, why=NO_SUCH_JOB),
)
def get_job(job_id: str, store: StoreDep) -> JobStatus:
    record = _job(store, job_id)
    return job_status(record, store.queued_ahead(record))


@router.head("/{job_id}/result", include_in_schema=False)  # players and download managers
@router.get(
    "/{job_id}/result",
    summary="Download a result: json, mcap, mot or mp4 (the annotated video)",
    response_class=Download,
    responses={
        **error_responses(400, 404, 409, 416, 422, why={
            **RANGE_ERRORS,
            404: "No such job, a job created without that format (options.formats), or a "
            "result that is gone.",
            409: "The job has not succeeded (yet).",
        }),
        200: _RESULT_CONTENT,
        **NOT_MODIFIED,
    },
)  # fmt: skip
def get_result(
    request: Request,
    job_id: str,
    store: StoreDep,
    files: FilesDep,
    format: Annotated[OutputFormat, Query(description="Which result.")] = OutputFormat.json,
) -> Download:
    record = _succeeded(_job(store, job_id))
    name = record.results.get(format.value)
    if name is None:
        asked = ", ".join(record.results) or "none"
        raise ApiError(
            ErrorType.not_found,
            f"job {job_id} was created without the {format.value!r} result (it has: {asked}); "
            "list the formats you need in options.formats",
        )
    path = files.result_file(record, name)
    if path is None:
        raise ApiError(ErrorType.not_found, f"the {format.value} result of job {job_id} is gone")
    download = f"{job_id}-{name}"
    # The video opens in a browser tab (inline) rather than as a download; Download answers
    # Range requests, which players need to seek (Safari to play at all).
    disposition = "inline" if format == OutputFormat.mp4 else "attachment"
    headers = {}
    if format == OutputFormat.json:
        # the JSON compresses about 7 to 1; the worker wrote the compressed copy once
        headers["Vary"] = "Accept-Encoding"
        if accepts_gzip(request.headers.get("accept-encoding")) and (
            packed := files.result_file(record, name, compressed=True)
        ):
            path, headers["Content-Encoding"] = packed, "gzip"
    return Download(
        path,
        media_type=MEDIA_TYPES[format],
        filename=download,
        content_disposition_type=disposition,
        headers=headers,
    )


def _succeeded(record: JobRecord) -> JobRecord:
    """``record``, a job that succeeded; else 409 saying what it is doing or why it ended."""
    if record.state == JobState.succeeded:
        return record
    job_id = record.id
    if record.state in (JobState.queued, JobState.running):
        total = record.frames_total if record.frames_total is not None else "?"
        raise ApiError(
            ErrorType.conflict,
            f"job {job_id} is {record.state.value} ({record.frames_done} of {total} frames): "
            f"results are served once it has succeeded; poll {status_url(job_id)}",
        )
    raise ApiError(
        ErrorType.conflict,
        f"job {job_id} {record.state.value} and has no results"
        + (f": {record.error}" if record.error else ""),
    )


@router.get(
    "/{job_id}/analytics",
    summary="The events and counts of a finished job's zones and lines",
    description="The zones and lines as they ran (in pixels), every event in time order and "
    "the counts (docs/analytics.md); `type` keeps the events of one type.",
    response_model=AnalyticsResult,
    responses=error_responses(404, 409, 422, why={
        404: "No such job, a job without options.analytics, or its analytics are gone.",
        409: "The job has not succeeded (yet).",
    }),
)  # fmt: skip
def get_analytics(
    job_id: str,
    store: StoreDep,
    files: FilesDep,
    type: Annotated[EventType | None, Query(description="Only the events of this type.")] = None,
) -> AnalyticsResult:
    record = _succeeded(_job(store, job_id))
    if not record.options.get("analytics"):
        raise ApiError(
            ErrorType.not_found,
            f"job {job_id} watched no zones or lines: give options.analytics when you submit "
            "a job (docs/analytics.md)",
        )
    path = files.result_file(record, ANALYTICS_FILE)
    if path is None:
        raise ApiError(ErrorType.not_found, f"the analytics of job {job_id} are gone")
    result = AnalyticsResult.model_validate_json(path.read_bytes())
    if type is not None:
        result.events = [event for event in result.events if event.type == type]
    return result


@router.get(
    "/{job_id}/events",
    summary="Live progress as server-sent events",
    description="`event: progress` with a ProgressEvent (JSON) whenever the job changes, then "
    "`event: end` with the final one, after which the stream closes.",
    response_class=StreamingResponse,
    responses={
        **error_responses(404, 503, why={**NO_SUCH_JOB, 503: _TOO_MANY_FOLLOWERS}),
        200: {
            "description": "The event stream: `progress` events, then one `end` event, each "
            "with a ProgressEvent as JSON in its `data` (the `end` of a job deleted meanwhile: "
            '`{"id": ..., "deleted": true}`), and `: keep-alive` comments. The schema is that '
            "of one event (OpenAPI 3.1 has no other way to say it).",
            "content": {"text/event-stream": {"schema": _EVENT}},
        },
    },
)
async def job_events(
    job_id: str, request: Request, store: StoreDep, settings: SettingsDep
) -> StreamingResponse:
    _job(store, job_id)
    state = request.app.state
    if state.event_streams >= settings.max_event_streams:
        raise ApiError(
            ErrorType.busy,
            f"{state.event_streams} clients follow job events already, the most this service "
            "serves (VTRACK_MAX_EVENT_STREAMS): poll GET /v1/jobs/{id} instead, or try again "
            "later",
            headers={"Retry-After": "5"},
        )

    def progress() -> tuple[JobRecord | None, str]:
        record = store.get(job_id)
        if record is None:
            return None, ""
        return record, progress_event(record, store.queued_ahead(record)).model_dump_json()

    async def stream():
        last, last_sent = None, time.monotonic()
        stopping: threading.Event = state.stopping
        state.event_streams += 1  # here, not before: a response that never starts is no follower
        try:
            while not (stopping.is_set() or await request.is_disconnected()):
                # the database off the event loop: hundreds of followers must not stall it
                record, data = await run_in_threadpool(progress)
                if record is None:
                    yield f'event: end\ndata: {{"id": "{job_id}", "deleted": true}}\n\n'
                    return
                if record.state.finished:
                    yield f"event: end\ndata: {data}\n\n"
                    return
                if data != last:
                    yield f"event: progress\ndata: {data}\n\n"
                    last, last_sent = data, time.monotonic()
                elif time.monotonic() - last_sent > KEEPALIVE_SECONDS:
                    yield ": keep-alive\n\n"
                    last_sent = time.monotonic()
                await asyncio.sleep(EVENT_POLL_SECONDS)
        finally:
            state.event_streams -= 1

    return StreamingResponse(
        stream(), media_type="text/event-stream", headers={"Cache-Control": "no-cache"}
    )


@router.delete(
    "/{job_id}",
    summary="Cancel a queued or running job, or delete a finished one with its files",
    status_code=status.HTTP_200_OK,
    responses={
        **error_responses(404, why=NO_SUCH_JOB),
        200: {"model": JobStatus, "description": "Queued: cancelled (state cancelled)."},
        202: {"model": JobStatus, "description": "Running: asked to stop (state follows)."},
        204: {"description": "Finished: deleted with its upload and results."},
    },
)
def delete_job(job_id: str, store: StoreDep, files: FilesDep) -> Response:
    record = _job(store, job_id)
    if record.state.finished:
        remove_job(files, store, record)
        log.info("job %s (%s) deleted with its files", job_id, record.state.value)
        return Response(status_code=status.HTTP_204_NO_CONTENT)
    new_state = store.request_cancel(job_id)
    if new_state == JobState.cancelled:
        log.info("job %s cancelled before it started", job_id)
    updated = _job(store, job_id)
    code = status.HTTP_202_ACCEPTED if new_state == JobState.running else status.HTTP_200_OK
    return Response(
        job_status(updated).model_dump_json(), status_code=code, media_type="application/json"
    )
