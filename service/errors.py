"""The service's error answers: an :class:`~api_schemas.common.ErrorResponse` for each, with
its :class:`~api_schemas.common.ErrorType` code, whoever answers (a route, a middleware, the
connection's protocol)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from fastapi import HTTPException
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from api_schemas.common import ERROR_STATUS, ErrorType
from service.pipelines import OptionsError

_TYPE_OF_STATUS = {
    400: ErrorType.bad_request,
    401: ErrorType.unauthorized,
    403: ErrorType.forbidden,
    404: ErrorType.not_found,
    405: ErrorType.method_not_allowed,
    408: ErrorType.timeout,
    409: ErrorType.conflict,
    413: ErrorType.payload_too_large,
    415: ErrorType.unsupported_media,
    416: ErrorType.range_not_satisfiable,
    422: ErrorType.validation_error,
    431: ErrorType.headers_too_large,
    503: ErrorType.unavailable,
    507: ErrorType.insufficient_storage,
}
"""The code of an HTTPException the framework raises (Starlette's 404 for an unknown path)."""


class ApiError(HTTPException):
    """An error answer of the service: its status follows from ``type`` (:data:`ERROR_STATUS`);
    ``errors``, for a validation error, lists each failed check."""

    def __init__(
        self,
        type: ErrorType,
        detail: str,
        *,
        errors: list[dict[str, Any]] | None = None,
        headers: Mapping[str, str] | None = None,
    ) -> None:
        super().__init__(ERROR_STATUS[type], detail, dict(headers) if headers else None)
        self.type = type
        self.errors = errors


def error_type(error: StarletteHTTPException) -> ErrorType:
    """The code of ``error``: its own, or the one of its status (500's for an unknown one)."""
    if isinstance(error, ApiError):
        return error.type
    return _TYPE_OF_STATUS.get(error.status_code, ErrorType.internal)


def error_body(type: ErrorType, detail: str, errors: list[dict[str, Any]] | None = None) -> dict:
    """The JSON of an ErrorResponse."""
    body: dict[str, Any] = {"type": type.value, "detail": detail}
    if errors is not None:
        body["errors"] = errors
    return body


def error_response(
    type: ErrorType,
    detail: str,
    *,
    errors: list[dict[str, Any]] | None = None,
    headers: Mapping[str, str] | None = None,
) -> JSONResponse:
    """The answer to an error of ``type``, with its status."""
    return JSONResponse(
        error_body(type, detail, errors), status_code=ERROR_STATUS[type], headers=headers
    )


def options_error(error: OptionsError, where: str) -> ApiError:
    """422 ``invalid_options`` for options the service cannot run; when one option is to blame
    (``error.loc``), ``errors`` locates it under ``where`` ('options' of an upload, 'body' of
    a stream)."""
    errors = None
    if error.loc is not None:
        errors = [{"loc": [where, *error.loc], "msg": error.message, "type": "value_error"}]
    return ApiError(ErrorType.invalid_options, str(error), errors=errors)
