"""The OpenAPI document as a contract: every status an operation can answer, each error an
ErrorResponse, and the request schemas FastAPI does not see.

FastAPI documents what the routes declare. The service also answers from outside them: its
middlewares and protocol refuse requests before any route runs (a missing token, a page of
another site, headers or a body too slow or too large, too many connections), an unknown
query parameter is refused for every route of ``/v1`` (:func:`~service.deps.
refuse_unknown_query_parameters`), an internal error is answered 500. :func:`install` makes
``app.openapi()`` add those statuses to the operations they apply to, declare FastAPI's own
422 as the ErrorResponse the service sends (:func:`service.app._validation_error`), and put
the schemas named by :func:`schema_ref` into the components.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI
from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, iter_route_contexts
from pydantic import BaseModel
from pydantic.json_schema import JsonSchemaMode, models_json_schema

from service.deps import refuse_unknown_query_parameters

SCHEMAS = "#/components/schemas/"
ERROR_REF = {"$ref": f"{SCHEMAS}ErrorResponse"}

_extra_models: set[tuple[type[BaseModel], JsonSchemaMode]] = set()
"""The models and modes :func:`schema_ref` named, for :func:`complete` to add."""

RETRY_AFTER = {
    "Retry-After": {
        "description": "Seconds to wait before trying again.",
        "schema": {"type": "integer", "minimum": 0},
    }
}

# Why each status that comes from outside the routes comes, said once for every operation.
TOKEN = (
    "No token, or not the one the service was configured with: send 'Authorization: Bearer "
    "<token>' (VTRACK_API_TOKEN; a service without a token answers no 401)."
)
SITE = (
    "Refused before it is read: the request of a web page of another site (its Origin) that "
    "would change something, or a host name that a service listening on loopback does not "
    "answer to (VTRACK_ALLOWED_HOSTS)."
)
TIMEOUT = (
    "The request's line and headers did not arrive within VTRACK_HEADER_SECONDS, or its body "
    "paused for VTRACK_BODY_IDLE_SECONDS (an upload: VTRACK_UPLOAD_IDLE_SECONDS); the "
    "connection is closed."
)
BODY_TOO_LARGE = (
    "The request body is over 64 KiB (an upload: over VTRACK_MAX_UPLOAD_BYTES, or an options "
    "part over its limit)."
)
UNKNOWN_QUERY = (
    "A query parameter the operation does not take, or an invalid one (or a JSON body that is "
    "not UTF-8): `errors` lists each failed check."
)
HEADERS_TOO_LARGE = "The request's line and headers are over 64 KiB; the connection is closed."
INTERNAL = "An internal error: the service's log has the details; tell its operator."
BUSY = (
    "The service has as many connections open as it serves at once (VTRACK_MAX_CONNECTIONS), "
    "or its shared job database (VTRACK_DATABASE_URL) cannot be reached just now: try again "
    "after Retry-After seconds."
)
STORAGE = (
    "The data folder's disk is full, or the folder cannot be written: its operator must free "
    "space or fix its permissions."
)


def schema_ref(model: type[BaseModel], mode: JsonSchemaMode = "validation") -> str:
    """The ``$ref`` of ``model``'s schema for a part of the document FastAPI does not see: the
    upload's ``options`` part, which its route reads itself (``mode`` 'validation': what the
    service accepts), or the events of a stream ('serialization': what it sends).
    :func:`install` puts the schema into the document's components; pydantic names it
    ``<Model>-Input`` or ``-Output`` where the two modes differ."""
    name, _ = _definitions(model, mode)
    _extra_models.add((model, mode))
    return SCHEMAS + name


def _definitions(
    model: type[BaseModel], mode: JsonSchemaMode
) -> tuple[str, dict[str, dict[str, Any]]]:
    """The component name of ``model``'s schema in ``mode``, and the definitions it needs,
    named as FastAPI names them: both modes are generated, so that pydantic tells them apart
    where they differ, and the other mode's are dropped."""
    other: JsonSchemaMode = "serialization" if mode == "validation" else "validation"
    keys, document = models_json_schema(
        [(model, mode), (model, other)], ref_template=SCHEMAS + "{model}"
    )
    name = keys[(model, mode)]["$ref"].removeprefix(SCHEMAS)
    dropped = "-Output" if mode == "validation" else "-Input"
    definitions = document.get("$defs", {})
    return name, {k: v for k, v in definitions.items() if not k.endswith(dropped)}


def _query_checked(app: FastAPI) -> set[tuple[str, str]]:
    """The (path, method) of every operation whose route refuses unknown query parameters."""

    def calls(dependant: Dependant) -> Iterator[Callable[..., Any] | None]:
        yield dependant.call
        for dependency in dependant.dependencies:
            yield from calls(dependency)

    return {
        (context.path_format, method.lower())
        # contexts: the routes of included routers with their prefixes (FastAPI keeps them
        # apart from app.routes' own)
        for context in iter_route_contexts(app.routes)
        if isinstance(route := context.original_route, APIRoute)
        and context.path_format is not None
        and refuse_unknown_query_parameters in calls(route.dependant)
        for method in route.methods or ()
    }


def _global_statuses(method: str, secured: bool, checks_query: bool) -> dict[int, str]:
    """The statuses an operation can answer whatever its route does, and why."""
    statuses = {403: SITE, 408: TIMEOUT, 431: HEADERS_TOO_LARGE, 500: INTERNAL, 503: BUSY}
    if secured:
        statuses[401] = TOKEN
    if method != "get":  # bodies are read (and limited) for every method but GET and HEAD
        statuses |= {413: BODY_TOO_LARGE, 507: STORAGE}
    if checks_query:
        statuses[422] = UNKNOWN_QUERY
    return statuses


def _add_status(responses: dict[str, Any], code: int, why: str) -> None:
    """Declare ``code`` with ``why`` as an ErrorResponse; where the route declared it already,
    keep its words and add ``why``, and keep its own body beside an ErrorResponse."""
    response = responses.setdefault(str(code), {})
    described = response.get("description")
    if not described or described in (HTTPStatus(code).phrase, "Validation Error"):
        response["description"] = why
    elif why not in described:
        response["description"] = f"{described} Or: {why}"
    media = response.setdefault("content", {}).setdefault("application/json", {})
    schema = media.get("schema")
    if schema is None or _is_validation_error(schema):
        media["schema"] = dict(ERROR_REF)
    elif schema != ERROR_REF and ERROR_REF not in schema.get("anyOf", []):
        media["schema"] = {"anyOf": [schema, dict(ERROR_REF)]}
    if code == 401:
        response.setdefault("headers", {})["WWW-Authenticate"] = {
            "description": "Bearer",
            "schema": {"type": "string"},
        }
    if code == 503:
        response.setdefault("headers", {}).update(RETRY_AFTER)


def _is_validation_error(schema: dict[str, Any]) -> bool:
    return schema.get("$ref") == f"{SCHEMAS}HTTPValidationError"


def _query_parameter_schema(schema: dict[str, Any]) -> dict[str, Any]:
    """A query parameter's schema without FastAPI's ``null`` branch: a query string carries
    no null (an absent parameter is the route's None)."""
    branches = [b for b in schema.get("anyOf", []) if b != {"type": "null"}]
    if "anyOf" not in schema or len(branches) == len(schema["anyOf"]):
        return schema
    rest = {k: v for k, v in schema.items() if k != "anyOf"}
    return {**branches[0], **rest} if len(branches) == 1 else {**rest, "anyOf": branches}


def _references(node: object) -> Iterator[str]:
    if isinstance(node, dict):
        if isinstance(node.get("$ref"), str):
            yield node["$ref"]
        for value in node.values():
            yield from _references(value)
    elif isinstance(node, list):
        for value in node:
            yield from _references(value)


def complete(document: dict[str, Any], app: FastAPI) -> dict[str, Any]:
    """``document`` (FastAPI's, for ``app``) with every status each operation can answer."""
    document = copy.deepcopy(document)
    schemas = document.setdefault("components", {}).setdefault("schemas", {})
    for model, mode in sorted(_extra_models, key=str):
        for name, definition in _definitions(model, mode)[1].items():
            schemas.setdefault(name, definition)
    query_checked = _query_checked(app)
    for path, operations in document.get("paths", {}).items():
        for method, operation in operations.items():
            secured = bool(operation.get("security"))
            checks_query = (path, method) in query_checked
            responses = operation.setdefault("responses", {})
            for code, why in _global_statuses(method, secured, checks_query).items():
                _add_status(responses, code, why)
            for response in responses.values():  # FastAPI's 422 of a route with parameters
                media = response.get("content", {}).get("application/json", {})
                if _is_validation_error(media.get("schema", {})):
                    media["schema"] = dict(ERROR_REF)
            for parameter in operation.get("parameters", []):
                if parameter.get("in") == "query" and "schema" in parameter:
                    parameter["schema"] = _query_parameter_schema(parameter["schema"])
            operation["responses"] = dict(sorted(responses.items()))
    for unused in ("HTTPValidationError", "ValidationError"):  # the first refers to the second
        if SCHEMAS + unused not in set(_references(document)):
            schemas.pop(unused, None)
    document["components"]["schemas"] = dict(sorted(schemas.items()))
    return document


def install(app: FastAPI) -> None:
    """Make ``app.openapi()`` (and so ``/openapi.json`` and the docs) answer the completed
    document, made once from FastAPI's (which FastAPI makes again when routes change)."""
    generate = app.openapi
    made: dict[str, Any] = {}

    def openapi() -> dict[str, Any]:
        source = generate()
        if made.get("source") is not source:
            made.update(source=source, document=complete(source, app))
        return made["document"]

    app.openapi = openapi  # type: ignore[method-assign]
