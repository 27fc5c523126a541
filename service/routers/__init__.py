"""One router per resource: jobs, streams, health, metrics."""

from __future__ import annotations

from typing import Any

from api_schemas.common import ErrorResponse


def error_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` for the error answers a route gives, each an ErrorResponse (401, a
    missing or wrong token, always can)."""
    return {code: {"model": ErrorResponse} for code in (401, *codes)}


BINARY_CONTENT = {"schema": {"type": "string", "format": "binary"}}
"""An OpenAPI media type entry for a file download."""
