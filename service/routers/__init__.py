"""One router per resource: jobs, streams, health, metrics."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from api_schemas.common import ErrorResponse


def error_responses(
    *codes: int, why: Mapping[int, str] | None = None
) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` for the error answers a route gives, each an ErrorResponse (401, a
    missing or wrong token, always can), described by ``why`` where it has the code."""
    why = why or {}
    return {
        code: {"model": ErrorResponse} | ({"description": why[code]} if code in why else {})
        for code in (401, *codes)
    }


BINARY_CONTENT = {"schema": {"type": "string", "format": "binary"}}
"""An OpenAPI media type entry for a file download."""
