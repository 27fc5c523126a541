"""What goes out to the sinks: a stream's zone and line events, and a job's summary when it
ends. Each has an idempotency key (the same event, computed or sent twice, has the same) and a
topic: ``cameras/<camera>/events/<type>`` and ``jobs/<id>/finished``, under the MQTT sink's
prefix, or in a webhook's ``X-Vtrack-Topic`` header."""

from __future__ import annotations

import json
from datetime import UTC, datetime

from api_schemas.analytics import AnalyticsCounts, AnalyticsEvent, CameraEvent
from api_schemas.jobs import JobState
from service.delivery.outbox import OutgoingEvent
from service.jobs.views import result_url

__all__ = ["job_summary", "stream_event"]


def stream_event(event: AnalyticsEvent, camera: str, run: str) -> OutgoingEvent:
    """``event`` of a camera's stream, keyed by camera, the tracker's ``run``, frame, track,
    type and name; the body is the event with its camera."""
    key = f"{camera}:{run}:{event.frame_index}:{event.track_id}:{event.type}:{event.name}"
    body = CameraEvent(camera=camera, **event.model_dump()).model_dump_json()
    return OutgoingEvent(key, f"cameras/{camera}/events/{event.type}", body)


def job_summary(
    job_id: str,
    state: JobState,
    *,
    filename: str | None,
    labels: dict[str, str],
    results: dict[str, str] | None = None,
    frames: int | None = None,
    error: str | None = None,
    warnings: list[str] | None = None,
    analytics: AnalyticsCounts | None = None,
) -> OutgoingEvent:
    """The summary of a job that ended (succeeded, failed or was cancelled): its state, where
    to fetch its results, and the counts of its zones and lines."""
    body = {
        "type": "job_finished",
        "job_id": job_id,
        "state": state.value,
        "finished_at": datetime.now(UTC).isoformat().replace("+00:00", "Z"),
        "filename": filename,
        "labels": labels,
        "frames": frames,
        "results": {fmt: result_url(job_id, fmt) for fmt in results or {}},
        "error": error,
        "warnings": warnings or [],
        "analytics": None
        if analytics is None
        else analytics.model_dump(mode="json", by_alias=True),
    }
    return OutgoingEvent(f"job:{job_id}", f"jobs/{job_id}/finished", json.dumps(body))
