"""Liveness and readiness: open to everyone, even with a token configured."""

from __future__ import annotations

import os

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from service.deps import PoolDep, SettingsDep, StoreDep, StreamsDep
from service.settings import Settings
from service.storage import writable_remedy

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
            "cannot be written (``detail`` says which and what to do)."
        }
    },
)
def readyz(
    store: StoreDep, pool: PoolDep, streams: StreamsDep, settings: SettingsDep
) -> JSONResponse:
    counts = store.counts_by_state()
    unwritable = _unwritable(settings)
    ready = pool.ready() and unwritable is None
    body = {
        "status": "ready" if ready else "starting",
        "workers": pool.size,
        "workers_ready": ready,
        "jobs": {state.value: n for state, n in counts.items()},
        "streams": streams.counts(),
        "zenoh": streams.unavailable or "ok",
    }
    if unwritable is not None:
        body["status"] = "unwritable"
        body["detail"] = unwritable
    elif not ready:
        body["detail"] = "no worker process is ready yet; try again in a few seconds"
    return JSONResponse(body, status_code=200 if ready else 503)


def _unwritable(settings: Settings) -> str | None:
    """Why uploads or results cannot be written (a folder made read-only or immutable, a file
    system remounted read-only), or None: such a service would refuse every job."""
    for folder in (settings.uploads_dir, settings.results_dir):
        folder = folder if folder.exists() else settings.data_dir  # made by the first job
        if not os.access(folder, os.W_OK):
            return f"the data folder cannot be written ({folder}): {writable_remedy()}"
    return None
