"""Accepting a received upload as a job: check the options, check the video, record it.

Nothing of HTTP here: the router receives the upload (:mod:`service.uploads`) and answers the
:class:`SubmitError` (and :class:`~service.pipelines.OptionsError`) raised here.
"""

from __future__ import annotations

import logging
import sqlite3
import uuid
from pathlib import Path
from typing import Any

import anyio
from pydantic import ValidationError

from api_schemas.common import ErrorType, error_message
from api_schemas.jobs import JobOptions
from service.frames import FrameSource, FrameSourceError
from service.jobs.files import JobFiles
from service.jobs.probing import ProbeInterrupted, VideoProber
from service.jobs.store import JobRecord, JobStore
from service.pipelines import PipelineResources, check_options
from service.settings import Settings
from service.storage import storage_problem
from service.uploads import ReceivedUpload

log = logging.getLogger(__name__)


def describe_validation(error: ValidationError) -> str:
    """One sentence for a pydantic error: each field and what was wrong with it (rules across
    fields, which belong to no one field, say what is wrong on their own)."""
    problems = []
    for item in error.errors():
        where = ".".join(str(part) for part in item["loc"])
        message = error_message(item)
        if item["type"] == "extra_forbidden":
            problems.append(f"unknown option '{where}'")
        else:
            problems.append(f"{where}: {message}" if where else message)
    return "; ".join(problems)


class SubmitError(Exception):
    """Why an upload is not accepted as a job: ``type`` says what kind of error (its HTTP
    status too), ``detail`` the sentence for the client, ``errors`` each failed check of
    options that fail their schema (located under ``options``)."""

    def __init__(
        self, type: ErrorType, detail: str, errors: list[dict[str, Any]] | None = None
    ) -> None:
        super().__init__(detail)
        self.type = type
        self.detail = detail
        self.errors = errors


def invalid_options(error: ValidationError) -> SubmitError:
    """The error for job options that fail their schema: the sentence, and each failed check
    for programs (``errors`` of ErrorResponse)."""
    return SubmitError(
        ErrorType.validation_error,
        f"invalid job options: {describe_validation(error)}. The options part is JSON "
        "with the fields of JobOptions (see /docs)",
        [
            {"loc": ["options", *item["loc"]], "msg": error_message(item), "type": item["type"]}
            for item in error.errors()
        ],
    )


def parse_options(raw: bytes | None) -> JobOptions:
    if raw is None or not raw.strip():
        return JobOptions()
    try:
        return JobOptions.model_validate_json(raw)
    except ValidationError as error:
        raise invalid_options(error) from None


def probe_video(prober: VideoProber, path: Path, size: int) -> FrameSource:
    """The upload's :class:`FrameSource`, probed in a helper process; ``invalid_video`` for
    no video."""
    if size == 0:
        raise SubmitError(
            ErrorType.invalid_video,
            "the 'video' part is empty: send a video file (MP4, AVI, MKV...)",
        )
    try:
        return prober.probe(path)
    except ProbeInterrupted:
        raise SubmitError(
            ErrorType.unavailable,
            "the service is stopping: send the video again once it is back",
        ) from None
    except FrameSourceError as error:
        reason = error.reason or "no frame could be read from it"
        raise SubmitError(
            ErrorType.invalid_video,
            f"the uploaded file is not a video this service can decode: {reason}; send a "
            "video file such as MP4 (H.264) or AVI (MJPEG)",
        ) from None


def new_job_id() -> str:
    """The id of a new job: 32 hex digits, random (not guessable from another job's)."""
    return uuid.uuid4().hex


async def submit(
    job_id: str,
    upload: ReceivedUpload,
    settings: Settings,
    store: JobStore,
    files: JobFiles,
    prober: VideoProber,
) -> JobRecord:
    """Check the upload received for ``job_id`` (into ``files.receiving(job_id)``) and queue it
    as a job; the upload is removed when it is refused.

    Raises
    ------
    SubmitError
        Options that fail their schema, no video, the service stopping, no room to record it.
    OptionsError
        Options the service cannot run on this video.
    """
    try:
        options = parse_options(upload.options)
        source = await anyio.to_thread.run_sync(probe_video, prober, upload.video_path, upload.size)
        check_options(options, PipelineResources.from_settings(settings), source)
        video_path = files.keep_upload(job_id, upload.video_path, upload.filename)
    except BaseException:
        upload.video_path.unlink(missing_ok=True)
        raise
    try:
        record = store.create(
            job_id,
            options.model_dump(mode="json"),
            video_path=video_path,
            result_dir=files.result_folder(job_id),
            video_filename=upload.filename,
            frames_total=source.frames_until(options.end) or None,
        )
    except BaseException as error:  # whatever it was, the upload is no job's: it goes
        files.remove_upload(video_path.name)
        is_storage = isinstance(error, sqlite3.OperationalError)
        problem = storage_problem(error) if is_storage else None
        if problem is None:
            raise
        raise SubmitError(
            ErrorType.insufficient_storage,
            f"{problem.problem}: the job was not recorded; {problem.remedy}, then send the "
            "video again",
        ) from None
    log.info(
        "job %s queued: %r, %d bytes, %d frames announced",  # %r: a name may hold a newline
        job_id,
        upload.filename,
        upload.size,
        source.frame_count,
    )
    return record
