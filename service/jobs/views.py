"""Job records -> the public models of the API."""

from __future__ import annotations

import time
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from api_schemas.jobs import JobLinks, JobOptions, JobProgress, JobState, JobStatus, ProgressEvent

if TYPE_CHECKING:  # the store's module sends jobs' summaries, which link to their results
    from service.jobs.store import JobRecord

API_PREFIX = "/v1/jobs"


def _time(value: float | None) -> datetime | None:
    return datetime.fromtimestamp(value, UTC) if value is not None else None


def status_url(job_id: str) -> str:
    return f"{API_PREFIX}/{job_id}"


def events_url(job_id: str) -> str:
    return f"{API_PREFIX}/{job_id}/events"


def result_url(job_id: str, fmt: str) -> str:
    return f"{API_PREFIX}/{job_id}/result?format={fmt}"


def job_progress(record: JobRecord, queued_ahead: int | None = None) -> JobProgress:
    total = record.frames_total
    done = record.frames_done
    if record.state == JobState.succeeded:
        fraction = 1.0
    elif total:
        fraction = min(done / total, 1.0)
    else:
        fraction = None
    eta = None
    if record.state == JobState.running and total and done and record.started_at is not None:
        # the rate of frames read, not fps (frames tracked): frames skipped by frame_step or
        # before start are read too, and count in frames_done and frames_total
        elapsed = max(time.time() - record.started_at, 0.0)
        eta = max(total - done, 0) * elapsed / done
    return JobProgress(
        frames_done=done,
        frames_total=total,
        fps=record.fps,
        fraction=fraction,
        eta_seconds=eta,
        queued_ahead=queued_ahead,
    )


def job_status(record: JobRecord, queued_ahead: int | None = None) -> JobStatus:
    results = {}
    if record.state == JobState.succeeded:
        results = {fmt: result_url(record.id, fmt) for fmt in record.results}
    return JobStatus(
        id=record.id,
        state=record.state,
        created_at=_time(record.created_at),
        started_at=_time(record.started_at),
        finished_at=_time(record.finished_at),
        progress=job_progress(record, queued_ahead),
        error=record.error if record.state != JobState.succeeded else None,
        warnings=record.warnings,
        attempts=record.attempts,
        video_filename=record.video_filename,
        options=JobOptions.from_stored(record.options),
        links=JobLinks(status=status_url(record.id), events=events_url(record.id), results=results),
    )


def progress_event(record: JobRecord, queued_ahead: int | None = None) -> ProgressEvent:
    return ProgressEvent(
        id=record.id,
        state=record.state,
        progress=job_progress(record, queued_ahead),
        error=record.error if record.state in (JobState.failed, JobState.cancelled) else None,
    )
