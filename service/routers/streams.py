"""``/v1/streams``: start, watch and stop live tracking of cameras that publish on Zenoh."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from fastapi import APIRouter, Response, status

from api_schemas.common import ErrorType
from api_schemas.jobs import OutputFormat
from api_schemas.streams import StreamDetail, StreamList, StreamSpec, StreamStatus
from service.deps import AuthDep, KnownQueryDep, StreamsDep
from service.errors import ApiError, options_error
from service.outputs.base import MEDIA_TYPES
from service.pipelines import OptionsError
from service.routers import BINARY_CONTENT, error_responses
from service.routers.downloads import NOT_MODIFIED, RANGE_ERRORS, Download
from service.streams.manager import StreamConflict, StreamNotFound
from service.streams.session import ZenohUnavailable

router = APIRouter(prefix="/v1/streams", tags=["streams"], dependencies=[AuthDep, KnownQueryDep])

T = TypeVar("T")

NO_SUCH_STREAM = {404: "No such stream: it was never started or was deleted."}
_START_ERRORS = {
    409: "The camera is tracked already, by this service or (its liveliness token says) by "
    "another instance.",
    422: "A body the schema refuses (`errors` lists each failed check), or options this "
    "service cannot run (a model it lacks, tracker options that contradict each other).",
    503: "Live streams are off (VTRACK_ZENOH_ENABLED=false) or Zenoh is unavailable.",
}


def _not_found(stream_id: str) -> ApiError:
    return ApiError(
        ErrorType.not_found,
        f"no stream {stream_id!r}: it was never started or was deleted (GET /v1/streams lists "
        "the streams)",
    )


def _call(stream_id: str, method: Callable[[str], T]) -> T:
    """``method(stream_id)``, with 404 for an unknown stream."""
    try:
        return method(stream_id)
    except StreamNotFound:
        raise _not_found(stream_id) from None


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=StreamStatus,
    responses=error_responses(*_START_ERRORS, why=_START_ERRORS),
    summary="Start tracking a camera",
)
def create_stream(spec: StreamSpec, streams: StreamsDep, response: Response) -> StreamStatus:
    """Subscribe to ``<prefix>/cameras/<camera>/frames`` and publish tracks on
    ``<prefix>/cameras/<camera>/tracks``, in a worker process of its own. 409 when the camera is
    tracked already (by this instance or, as its liveliness token shows, by another)."""
    try:
        created = streams.create(spec)
    except ZenohUnavailable as error:
        raise ApiError(ErrorType.unavailable, str(error)) from None
    except StreamConflict as error:
        raise ApiError(ErrorType.conflict, str(error)) from None
    except OptionsError as error:
        raise options_error(error, "body") from None
    response.headers["Location"] = f"/v1/streams/{created.id}"
    return created


@router.get("", response_model=StreamList, responses=error_responses(), summary="List the streams")
def list_streams(streams: StreamsDep) -> StreamList:
    return StreamList(streams=streams.list())


@router.get(
    "/{stream_id}",
    response_model=StreamDetail,
    responses=error_responses(404, why=NO_SUCH_STREAM),
    summary="A stream's status and current tracks",
)
def get_stream(stream_id: str, streams: StreamsDep) -> StreamDetail:
    return _call(stream_id, streams.detail)


@router.delete(
    "/{stream_id}",
    response_model=StreamStatus,
    responses={
        **error_responses(
            404,
            409,
            why={**NO_SUCH_STREAM, 409: "It runs again (started since it was stopped)."},
        ),
        200: {"description": "A running stream was stopped: its final status."},
        204: {"description": "A stopped stream was deleted with its recordings."},
    },
    summary="Stop a stream (then, a second time, delete it)",
)
def delete_stream(stream_id: str, streams: StreamsDep) -> StreamStatus | Response:
    """A running stream is stopped: its worker ends, its recording is finished, and its final
    status is returned (200). A stopped stream is deleted with its recordings (204)."""
    current = _call(stream_id, streams.status)
    if current.state.value != "stopped":
        return _call(stream_id, streams.stop)
    try:
        streams.remove(stream_id)
    except StreamNotFound:
        raise _not_found(stream_id) from None
    except StreamConflict as error:
        raise ApiError(ErrorType.conflict, str(error)) from None
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.head("/{stream_id}/recordings/{name}", include_in_schema=False)  # as a job's result
@router.get(
    "/{stream_id}/recordings/{name}",
    response_class=Download,
    responses={
        **error_responses(
            400,
            404,
            416,
            why={
                **RANGE_ERRORS,
                404: "No such stream, or no such finished recording of it.",
            },
        ),
        200: {"content": {MEDIA_TYPES[OutputFormat.mcap]: BINARY_CONTENT}},
        **NOT_MODIFIED,
    },
    summary="Download a finished MCAP recording",
)
def get_recording(stream_id: str, name: str, streams: StreamsDep) -> Download:
    recordings = {p.name: p for p in _call(stream_id, streams.recordings)}
    if name not in recordings:
        if recordings or _call(stream_id, streams.status).spec.record:
            why = (
                "a recording is finished at the end of its segment (record_segment), when the "
                "tracks end and when the stream stops; finished: "
                f"{sorted(recordings) or 'none yet'}"
            )
        else:
            why = 'the stream does not record (start it with "record": true)'
        raise ApiError(
            ErrorType.not_found,
            f"stream {stream_id!r} has no finished recording {name!r}: {why}",
        )
    return Download(recordings[name], media_type=MEDIA_TYPES[OutputFormat.mcap], filename=name)
