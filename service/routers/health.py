"""Liveness and readiness: open to everyone, even with a token configured."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from api_schemas.health import DefaultDetector, Health, NetworkModel, Readiness
from api_schemas.jobs import DetectorOptions, JobState, PeopleTrackerOptions
from service.deps import FilesDep, PoolDep, SettingsDep, StoreDep, StreamsDep
from service.jobs.files import JobFiles
from service.pipelines import PipelineResources, choose_detector, choose_networks
from service.settings import Settings
from service.storage import FREE_SPACE, free_bytes, writable_remedy

router = APIRouter(tags=["health"])

# HEAD beside GET (out of the schema): load balancers and uptime monitors often probe with it.


@router.head("/healthz", include_in_schema=False)
@router.get("/healthz", summary="The process answers")
def healthz() -> Health:
    return Health(status="ok")


@router.head("/readyz", include_in_schema=False)
@router.get(
    "/readyz",
    summary="The service can take jobs: the store opens, a worker is ready, the folders are "
    "writable",
    response_model=Readiness,
    responses={
        503: {
            "model": Readiness,
            "description": "Not ready: no worker process is ready (yet), or the data folder "
            "cannot be written or its disk is full (``status`` says which, ``detail`` what to "
            "do).",
        }
    },
)
def readyz(
    store: StoreDep, pool: PoolDep, streams: StreamsDep, settings: SettingsDep, files: FilesDep
) -> JSONResponse:
    counts = store.counts_by_state()
    unwritable = _unwritable(files)
    full = _full(settings)
    workers_ready = pool.ready()
    ready = workers_ready > 0 and unwritable is None and full is None
    here = len(store.running(settings.instance)) if store.shared else counts[JobState.running]
    readiness = Readiness(
        status="ready" if ready else "starting",
        instance=settings.instance,
        jobs_here=here,
        workers=pool.size,
        workers_ready=workers_ready,  # a count, as workers is (was true once one was)
        jobs=counts,
        streams=streams.counts(),
        zenoh=streams.unavailable or "ok",
        detector=_default_detector(settings),
        **_default_networks(settings),
    )
    if unwritable is not None:
        readiness.status, readiness.detail = "unwritable", unwritable
    elif full is not None:
        readiness.status, readiness.detail = "full", full
    elif not ready:
        readiness.detail = "no worker process is ready yet; try again in a few seconds"
    # detail only when there is something to say, as before the model
    body = readiness.model_dump(mode="json", exclude={"detail"} if ready else None)
    return JSONResponse(body, status_code=200 if ready else 503)


def _default_detector(settings: Settings) -> DefaultDetector:
    """What a job's detector 'auto' runs now: the CNN and its model, or the embedded detector
    and how to install the model (a models folder can be filled while the service runs)."""
    choice = choose_detector(DetectorOptions(), PipelineResources.from_settings(settings))
    return DefaultDetector(
        name=choice.options.name, model=choice.options.model, warning=choice.warning
    )


def _default_networks(settings: Settings) -> dict[str, NetworkModel | None]:
    """What a people job's tracker.pose and tracker.reid left unset run now: the model's name
    when the service has the network's model, else None (the tracker goes without)."""
    tracker = choose_networks(
        PeopleTrackerOptions(), PipelineResources.from_settings(settings)
    ).tracker
    return {
        network: NetworkModel(model=getattr(tracker, f"{network}_model"))
        if getattr(tracker, network)
        else None
        for network in ("pose", "reid")
    }


def _unwritable(files: JobFiles) -> str | None:
    """Why uploads or results cannot be written (a folder made read-only or immutable, a file
    system remounted read-only), or None: such a service would refuse every job."""
    folder = files.unwritable()
    if folder is None:
        return None
    return f"the data folder cannot be written ({folder}): {writable_remedy()}"


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
