"""FastAPI dependencies and their aliases: what a route needs, taken from the app's state."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.jobs.store import JobStore
from service.jobs.workers import WorkerPool
from service.settings import Settings
from service.streams.manager import StreamManager

_bearer = HTTPBearer(auto_error=False, description="The token set in VTRACK_API_TOKEN.")


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_store(request: Request) -> JobStore:
    return request.app.state.store


def get_pool(request: Request) -> WorkerPool:
    return request.app.state.pool


def get_streams(request: Request) -> StreamManager:
    return request.app.state.streams


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[JobStore, Depends(get_store)]
PoolDep = Annotated[WorkerPool, Depends(get_pool)]
StreamsDep = Annotated[StreamManager, Depends(get_streams)]


TOKEN_MISSING = (
    "this service needs a token: send the header 'Authorization: Bearer <token>' with the "
    "token it was configured with (VTRACK_API_TOKEN)"
)


def token_accepted(settings: Settings, presented: str | None) -> bool:
    """True without a configured token, or when ``presented`` is that token."""
    if settings.api_token is None:
        return True
    expected = settings.api_token.get_secret_value()
    return presented is not None and secrets.compare_digest(presented.encode(), expected.encode())


def require_token(
    settings: SettingsDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """When ``VTRACK_API_TOKEN`` is set, the request must carry it as a bearer token."""
    if not token_accepted(settings, credentials.credentials if credentials else None):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED, TOKEN_MISSING, headers={"WWW-Authenticate": "Bearer"}
        )


AuthDep = Depends(require_token)
