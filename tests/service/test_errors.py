"""The error answers' codes: each with its status, the framework's errors given one too."""

from __future__ import annotations

from fastapi import HTTPException

from api_schemas.common import ERROR_STATUS, ErrorResponse, ErrorType
from service.errors import ApiError, error_body, error_type


def test_every_code_has_its_status_and_keeps_it_through_an_api_error():
    assert set(ERROR_STATUS) == set(ErrorType)
    for code in ErrorType:
        error = ApiError(code, "why")
        assert (error.status_code, error_type(error)) == (ERROR_STATUS[code], code)
        assert 400 <= error.status_code < 600


def test_a_framework_error_gets_the_code_of_its_status():
    # Starlette's 404 for a path that is none, FastAPI's 400 for a body it cannot parse
    assert error_type(HTTPException(404)) == ErrorType.not_found
    assert error_type(HTTPException(400)) == ErrorType.bad_request
    assert error_type(HTTPException(418)) == ErrorType.internal  # none of ours: no other fits


def test_an_error_body_is_an_error_response_with_checks_only_for_validation():
    plain = error_body(ErrorType.conflict, "not yet")
    assert plain == {"type": "conflict", "detail": "not yet"}
    checks = [{"loc": ["body", "x"], "msg": "no", "type": "extra_forbidden"}]
    body = error_body(ErrorType.validation_error, "invalid request: body.x: no", checks)
    assert ErrorResponse.model_validate(body).errors[0].loc == ["body", "x"]
