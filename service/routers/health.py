"""Liveness and readiness: open to everyone, even with a token configured."""

from __future__ import annotations

import os

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from api_schemas.jobs import DetectorOptions, PeopleTrackerOptions
from service.deps import PoolDep, SettingsDep, StoreDep, StreamsDep
from service.pipelines import PipelineResources, choose_detector, choose_networks
from service.settings import Settings
from service.storage import FREE_SPACE, free_bytes, writable_remedy

router = APIRouter(tags=["health"])

# HEAD beside GET (out of the schema): load balancers and uptime monitors often probe with it.


@router.head("/healthz", include_in_schema=False)
@router.get("/healthz", summary="The process answers")
def healthz() -> dict[str, str]:
    return {"status": "ok"}


@router.head("/readyz", include_in_schema=False)
@router.get(
    "/readyz",
    summary="The service can take jobs: the store opens, a worker is ready, the folders are "
    "writable",
    responses={
        503: {
            "description": "Not ready: no worker process is ready (yet), or the data folder "
            "cannot be written or its disk is full (``detail`` says which and what to do)."
        }
    },
)
def readyz(
    store: StoreDep, pool: PoolDep, streams: StreamsDep, settings: SettingsDep
) -> JSONResponse:
    counts = store.counts_by_state()
    unwritable = _unwritable(settings)
    full = _full(settings)
    workers_ready = pool.ready()
    ready = workers_ready > 0 and unwritable is None and full is None
    body = {
        "status": "ready" if ready else "starting",
        "workers": pool.size,
        "workers_ready": workers_ready,  # a count, as workers is (was true once one was)
        "jobs": {state.value: n for state, n in counts.items()},
        "streams": streams.counts(),
        "zenoh": streams.unavailable or "ok",
        "detector": _default_detector(settings),
        **_default_networks(settings),
    }
    if unwritable is not None:
        body["status"] = "unwritable"
        body["detail"] = unwritable
    elif full is not None:
        body["status"] = "full"
        body["detail"] = full
    elif not ready:
        body["detail"] = "no worker process is ready yet; try again in a few seconds"
    return JSONResponse(body, status_code=200 if ready else 503)


def _default_detector(settings: Settings) -> dict[str, str | None]:
    """What a job's detector 'auto' runs now: the CNN and its model, or the embedded detector
    and how to install the model (a models folder can be filled while the service runs)."""
    choice = choose_detector(DetectorOptions(), PipelineResources.from_settings(settings))
    return {
        "name": choice.options.name,
        "model": choice.options.model,
        "warning": choice.warning,
    }


def _default_networks(settings: Settings) -> dict[str, dict[str, str] | None]:
    """What a people job's tracker.pose and tracker.reid left unset run now: ``{"model":
    name}`` when the service has the network's model, else None (the tracker goes without)."""
    tracker = choose_networks(
        PeopleTrackerOptions(), PipelineResources.from_settings(settings)
    ).tracker
    return {
        network: {"model": getattr(tracker, f"{network}_model")}
        if getattr(tracker, network)
        else None
        for network in ("pose", "reid")
    }


def _unwritable(settings: Settings) -> str | None:
    """Why uploads or results cannot be written (a folder made read-only or immutable, a file
    system remounted read-only), or None: such a service would refuse every job."""
    for folder in (settings.uploads_dir, settings.results_dir):
        folder = folder if folder.exists() else settings.data_dir  # made by the first job
        if not os.access(folder, os.W_OK):
            return f"the data folder cannot be written ({folder}): {writable_remedy()}"
    return None


def _full(settings: Settings) -> str | None:
    """Why the data folder's disk can take no upload (less free space than
    ``VTRACK_MIN_FREE_MB``), or None."""
    free = free_bytes(settings.data_dir) / 1e6
    if free >= settings.min_free_mb:
        return None
    return (
        f"the data folder's disk has {free:.0f} MB free, under VTRACK_MIN_FREE_MB "
        f"({settings.min_free_mb:g}): {FREE_SPACE}"
    )
