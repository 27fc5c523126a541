"""Accepting an upload as a job: receive, check the options, check the video, record it."""

from __future__ import annotations

import logging
import sqlite3
import uuid
from pathlib import Path

from fastapi import HTTPException, Request, status
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from api_schemas.common import error_message
from api_schemas.jobs import JobOptions
from service.frames import FrameSource, FrameSourceError
from service.jobs.files import JobFiles
from service.jobs.probing import ProbeInterrupted, VideoProber
from service.jobs.store import JobRecord, JobStore
from service.pipelines import OptionsError, PipelineResources, check_options
from service.settings import Settings
from service.storage import storage_problem
from service.uploads import receive_upload

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


class InvalidOptions(HTTPException):
    """422 for job options that fail their schema: the sentence, and each failed check for
    programs (``errors`` of ErrorResponse, located under ``options``)."""

    def __init__(self, error: ValidationError) -> None:
        super().__init__(
            422,
            f"invalid job options: {describe_validation(error)}. The options part is JSON "
            "with the fields of JobOptions (see /docs)",
        )
        self.errors = [
            {"loc": ["options", *item["loc"]], "msg": error_message(item), "type": item["type"]}
            for item in error.errors()
        ]


def parse_options(raw: bytes | None) -> JobOptions:
    if raw is None or not raw.strip():
        return JobOptions()
    try:
        return JobOptions.model_validate_json(raw)
    except ValidationError as error:
        raise InvalidOptions(error) from None


def probe_video(prober: VideoProber, path: Path, size: int) -> FrameSource:
    """The upload's :class:`FrameSource`, probed in a helper process; 415 for no video."""
    if size == 0:
        raise HTTPException(
            status.HTTP_415_UNSUPPORTED_MEDIA_TYPE,
            "the 'video' part is empty: send a video file (MP4, AVI, MKV...)",
        )
    try:
        return prober.probe(path)
    except ProbeInterrupted:
        raise HTTPException(
            status.HTTP_503_SERVICE_UNAVAILABLE,
            "the service is stopping: send the video again once it is back",
        ) from None
    except FrameSourceError as error:
        reason = error.reason or "no frame could be read from it"
        raise HTTPException(
            status.HTTP_415_UNSUPPORTED_MEDIA_TYPE,
            f"the uploaded file is not a video this service can decode: {reason}; send a "
            "video file such as MP4 (H.264) or AVI (MJPEG)",
        ) from None


async def submit(
    request: Request, settings: Settings, store: JobStore, files: JobFiles
) -> JobRecord:
    """Receive the upload of ``request`` into ``files`` and queue it as a job."""
    job_id = uuid.uuid4().hex
    receiving = files.receiving(job_id)
    upload = await receive_upload(
        request, receiving, settings.max_upload_bytes, settings.upload_idle_seconds
    )
    try:
        options = parse_options(upload.options)
        prober = request.app.state.prober
        source = await run_in_threadpool(probe_video, prober, upload.video_path, upload.size)
        try:
            check_options(options, PipelineResources.from_settings(settings), source)
        except OptionsError as error:
            raise HTTPException(422, str(error)) from None
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
        raise HTTPException(
            status.HTTP_507_INSUFFICIENT_STORAGE,
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
