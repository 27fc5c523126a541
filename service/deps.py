"""FastAPI dependencies and their aliases: what a route needs, taken from the app's state."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, Request
from fastapi.dependencies.models import Dependant
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from api_schemas.common import ErrorType
from service.errors import ApiError
from service.jobs.files import JobFiles
from service.jobs.store import JobStore
from service.jobs.workers import WorkerPool
from service.settings import Settings
from service.streams.manager import StreamManager

_bearer = HTTPBearer(auto_error=False, description="The token set in VTRACK_API_TOKEN.")


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_store(request: Request) -> JobStore:
    return request.app.state.store


def get_files(request: Request) -> JobFiles:
    return request.app.state.files


def get_pool(request: Request) -> WorkerPool:
    return request.app.state.pool


def get_streams(request: Request) -> StreamManager:
    return request.app.state.streams


SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[JobStore, Depends(get_store)]
FilesDep = Annotated[JobFiles, Depends(get_files)]
PoolDep = Annotated[WorkerPool, Depends(get_pool)]
StreamsDep = Annotated[StreamManager, Depends(get_streams)]


def token_refusal(settings: Settings, authorization: str | None) -> str | None:
    """Why a request with this ``Authorization`` header is refused, or None when it may pass
    (no token configured, or the header carries it as a bearer token)."""
    if settings.api_token is None:
        return None
    if not authorization:
        return (
            "this service needs a token: send the header 'Authorization: Bearer <token>' with "
            "the token it was configured with (VTRACK_API_TOKEN)"
        )
    scheme, _, presented = authorization.strip().partition(" ")
    presented = presented.strip()
    if scheme.lower() != "bearer" or not presented:
        return (
            f"the Authorization header must read 'Bearer <token>' (it has the scheme "
            f"{scheme!r}{'' if presented else ' and no token'})"
        )
    expected = settings.api_token.get_secret_value().encode()
    if not secrets.compare_digest(presented.encode(), expected):
        return "the token sent is not the one this service was configured with (VTRACK_API_TOKEN)"
    return None


def require_token(
    settings: SettingsDep,
    request: Request,
    # declared for the OpenAPI security scheme and the docs' Authorize button; the header
    # itself is read raw, to tell a missing token, another scheme and a wrong token apart
    _: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """When ``VTRACK_API_TOKEN`` is set, the request must carry it as a bearer token."""
    refusal = token_refusal(settings, request.headers.get("authorization"))
    if refusal is not None:
        raise ApiError(ErrorType.unauthorized, refusal, headers={"WWW-Authenticate": "Bearer"})


AuthDep = Depends(require_token)


def _query_names(dependant: Dependant) -> set[str]:
    """The query parameters a route's function and its dependencies take."""
    return {p.alias for p in dependant.query_params}.union(
        *(_query_names(d) for d in dependant.dependencies)
    )


def refuse_unknown_query_parameters(request: Request) -> None:
    """A query parameter the route does not take is refused (422), as an unknown field of a
    job's options is: a misspelt filter (``?stat=succeeded``) would otherwise list every job."""
    route = request.scope.get("route")
    if not isinstance(route, APIRoute):
        return
    known = _query_names(route.dependant)
    unknown = sorted(set(request.query_params) - known)
    if unknown:
        takes = f"it takes {', '.join(sorted(known))}" if known else "it takes none"
        raise RequestValidationError(
            [
                {
                    "type": "extra_forbidden",
                    "loc": ("query", name),
                    "msg": f"not a query parameter of this route ({takes})",
                    "input": request.query_params[name],
                }
                for name in unknown
            ]
        )


KnownQueryDep = Depends(refuse_unknown_query_parameters)
