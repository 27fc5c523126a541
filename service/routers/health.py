"""Liveness and readiness: open to everyone, even with a token configured."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from service.deps import PoolDep, StoreDep, StreamsDep

router = APIRouter(tags=["health"])

# HEAD beside GET (out of the schema): load balancers and uptime monitors often probe with it.


@router.head("/healthz", include_in_schema=False)
@router.get("/healthz", summary="The process answers")
def healthz() -> dict[str, str]:
    return {"status": "ok"}


@router.head("/readyz", include_in_schema=False)
@router.get(
    "/readyz",
    summary="The service can take jobs: the store opens and a worker is ready",
    responses={503: {"description": "Not ready (yet): no worker process is ready."}},
)
def readyz(store: StoreDep, pool: PoolDep, streams: StreamsDep) -> JSONResponse:
    counts = store.counts_by_state()
    ready = pool.ready()
    body = {
        "status": "ready" if ready else "starting",
        "workers": pool.size,
        "workers_ready": ready,
        "jobs": {state.value: n for state, n in counts.items()},
        "streams": streams.counts(),
        "zenoh": streams.unavailable or "ok",
    }
    if not ready:
        body["detail"] = "no worker process is ready yet; try again in a few seconds"
    return JSONResponse(body, status_code=200 if ready else 503)
