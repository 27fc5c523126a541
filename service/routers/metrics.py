"""Prometheus metrics."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from service.deps import AuthDep
from service.routers import error_responses

router = APIRouter(tags=["metrics"], dependencies=[AuthDep])


@router.get(
    "/metrics",
    summary="Prometheus metrics: jobs by state, frames processed, processing time",
    response_class=Response,
    responses={
        **error_responses(),
        200: {"content": {"text/plain": {"schema": {"type": "string"}}}},
    },
)
def metrics(request: Request) -> Response:
    return Response(generate_latest(request.app.state.registry), media_type=CONTENT_TYPE_LATEST)
