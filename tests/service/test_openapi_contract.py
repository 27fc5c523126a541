"""The API's OpenAPI document is a contract the service keeps (issue 78).

schemathesis generates requests from the service's own ``/openapi.json``, valid and invalid,
and sends them to a real service on loopback (``vtrack serve`` with an API token, a few real
jobs and streams for the generated ids to name: ``benchmarks/api_fuzz.py``'s set-up); every
answer must pass each of schemathesis's default checks: no server error, a status, content type
and headers the document declares for the operation, a body its schema takes, an invalid
request refused and a valid one accepted. The failures that are no breach (a generated file is
no video, a model this service lacks...: ``EXPECTED`` there, each with why) are dropped
narrowly, by operation, check, status and words.

A few dozen requests per operation keep this under a minute; ``benchmarks/api_fuzz.py`` is the
longer run (up to 1000 per operation, and stateful sequences), with its figures in
docs/benchmarks.md.
"""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest
import schemathesis
from pydantic import ValidationError
from schemathesis.config import SchemathesisConfig

from api_schemas import JobOptions, StreamSpec
from api_schemas.common import ERROR_STATUS, ErrorType
from service.app import create_app
from tests.conftest import benchmark_module, documented_commands
from tests.service.conftest import error_of

EXAMPLES = 50
"""Most generated requests per operation in the fuzzing phase (the examples and coverage phases
add their own): about 900 requests in all, 13 s for this file alone on 2 cores."""
SEED = 78

with benchmark_module("api_fuzz") as fuzz:  # its functions keep working once it is unloaded
    pass

RUN = fuzz.Run()
"""The service under test, filled in by the ``service`` fixture; the hooks read it as the
requests are generated and sent."""

# The schema is the app's document, loaded here for pytest to make a test per operation (pytest
# 9 broke schemathesis's loader from a fixture, which would load the running service's);
# ``service`` checks that the service serves the very same. Stateful sequences are the
# benchmark's: the pytest integration runs operations one by one.
schema = fuzz.add_hooks(
    schemathesis.openapi.from_dict(
        create_app().openapi(),
        config=SchemathesisConfig.from_dict(
            fuzz.fuzz_config(EXAMPLES, SEED, ("examples", "coverage", "fuzzing"))
        ),
    ),
    RUN,
)


@pytest.fixture(scope="module")
def service(tmp_path_factory) -> Iterator[object]:
    with fuzz.fuzzed_service(tmp_path_factory.mktemp("contract")) as (RUN.service, RUN.janitor):
        with RUN.service.server.client() as client:
            served = client.get("/openapi.json").json()
        assert served == json.loads(json.dumps(create_app().openapi()))
        yield RUN.service
    RUN.service = RUN.janitor = None


@schema.parametrize()
def test_every_answer_keeps_the_contract(case, service) -> None:
    # an event stream is read to its first event (max-stream-events in the configuration)
    case.call_and_validate(base_url=service.server.url, timeout=30)


@pytest.mark.parametrize(
    ("label", "status", "body", "reason"),
    [
        (
            "POST /v1/jobs",
            415,
            {"detail": "the uploaded file is not a video"},
            "a generated file is no video",
        ),
        (
            "POST /v1/streams",
            422,
            {"detail": "detector 'dpm' needs a voc-release5 model, and this service has none"},
            "a model the service lacks",
        ),
        (
            "POST /v1/jobs",
            422,
            {
                "detail": "x",
                "errors": [
                    {
                        "loc": ["options"],
                        "msg": "end (1 s) must come after start (2 s)",
                        "type": "value_error",
                    }
                ],
            },
            "end before start",
        ),
        # a breach stays one: a refusal of the schema's own (errors), an upload's parts
        (
            "POST /v1/streams",
            422,
            {"detail": "x", "errors": [{"loc": ["body", "camera"], "msg": "x", "type": "x"}]},
            None,
        ),
        ("POST /v1/jobs", 422, {"detail": "unexpected form part 'x': send the video"}, None),
        ("POST /v1/streams", 415, {"detail": "x"}, None),
        ("POST /v1/streams", 500, {"detail": "internal error"}, None),
    ],
)
def test_only_named_refusals_of_valid_requests_are_dropped(label, status, body, reason):
    assert fuzz.refusal_reason(label, status, body) == reason


def _document() -> dict:
    return create_app().openapi()


def test_every_error_is_an_error_response_and_no_other() -> None:
    document = _document()
    schemas = document["components"]["schemas"]
    # FastAPI's own 422 model is gone: the service answers an ErrorResponse
    assert not {"HTTPValidationError", "ValidationError"} & set(schemas)
    # each error carries its code, and the document lists the codes
    assert schemas["ErrorResponse"]["required"] == ["type", "detail"]
    assert schemas["ErrorType"]["enum"] == [code.value for code in ErrorType]
    assert all(f"``{code.value}`` ({ERROR_STATUS[code]})" in schemas["ErrorType"]["description"]
               for code in ErrorType)  # fmt: skip
    error = {"$ref": "#/components/schemas/ErrorResponse"}
    for path, operations in document["paths"].items():
        for method, operation in operations.items():
            responses = operation["responses"]
            where = f"{method.upper()} {path}"
            # what any request can meet, whatever the route
            assert {"403", "408", "431", "500", "503"} <= set(responses), where
            assert ("401" in responses) == (path not in ("/healthz", "/readyz")), where
            assert ("413" in responses) == (method != "get"), where
            assert ("422" in responses) == path.startswith("/v1/"), where
            for code, response in responses.items():
                if int(code) < 400:
                    continue
                schema = response["content"]["application/json"]["schema"]
                assert schema == error or error in schema["anyOf"], (where, code)
                assert response["description"] not in ("Validation Error", "Not Found"), where


def test_every_success_has_a_body_schema() -> None:
    paths = _document()["paths"]
    assert paths["/healthz"]["get"]["responses"]["200"]["content"]["application/json"] == {
        "schema": {"$ref": "#/components/schemas/Health"}
    }
    ready = paths["/readyz"]["get"]["responses"]
    assert ready["200"]["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/Readiness"
    }
    assert ready["503"]["content"]["application/json"]["schema"]["anyOf"][0] == {
        "$ref": "#/components/schemas/Readiness"
    }
    deleted = paths["/v1/jobs/{job_id}"]["delete"]["responses"]
    for code in ("200", "202"):
        assert deleted[code]["content"]["application/json"]["schema"] == {
            "$ref": "#/components/schemas/JobStatus"
        }
    stopped = paths["/v1/streams/{stream_id}"]["delete"]["responses"]["200"]
    assert stopped["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/StreamStatus"
    }
    event = paths["/v1/jobs/{job_id}/events"]["get"]["responses"]["200"]["content"]
    data = event["text/event-stream"]["schema"]["properties"]["data"]
    assert data["contentMediaType"] == "application/json"


def test_rules_across_fields_are_in_the_request_schemas_only() -> None:
    document = _document()
    schemas = document["components"]["schemas"]
    upload = document["paths"]["/v1/jobs"]["post"]["requestBody"]["content"]
    options = upload["multipart/form-data"]["schema"]["properties"]["options"]
    assert options["$ref"] == "#/components/schemas/JobOptions-Input"
    assert upload["multipart/form-data"]["schema"]["additionalProperties"] is False
    for name in ("JobOptions-Input", "DetectorOptions-Input", "PeopleTrackerOptions-Input"):
        assert schemas[name]["allOf"], name
    stream = document["paths"]["/v1/streams"]["post"]["requestBody"]["content"]
    assert stream["application/json"]["schema"] == {"$ref": "#/components/schemas/StreamSpec-Input"}
    assert schemas["StreamSpec-Input"]["allOf"]
    # what the service answers keeps the options as they were accepted, by the rules of then
    for name in ("JobOptions", "StreamSpec-Output", "DetectorOptions-Output"):
        assert "allOf" not in schemas[name], name


def test_finished_after_is_documented_as_it_is_taken(service) -> None:
    parameters = _document()["paths"]["/v1/jobs"]["get"]["parameters"]
    finished_after = next(p for p in parameters if p["name"] == "finished_after")
    assert finished_after["schema"]["type"] == "string"
    assert finished_after["schema"]["format"] == "date-time"
    # before: a number was taken as a Unix time (one over 2e10 as milliseconds), 200
    with service.server.client() as client:
        for number in ("1700000000", "0.5", "1700000000000"):
            refused = client.get("/v1/jobs", params={"finished_after": number})
            body = error_of(refused, "validation_error")
            assert "a number is not read as a Unix time" in body["detail"], number
        since = client.get("/v1/jobs", params={"finished_after": "2026-11-26T08:00:00Z"})
        assert since.status_code == 200


@pytest.mark.parametrize(
    ("model", "body", "taken"),
    [
        # JSON Schema's integer takes 2.0 (was: refused by strict pydantic)
        ("JobOptions", '{"frame_step": 2.0, "tracker": {"seed": 793.0}}', True),
        ("JobOptions", '{"frame_step": 2.5}', False),
        ("JobOptions", '{"frame_step": true}', False),
        # a stream's numbers and flags are strict (were: false as 0 s, "true" as a flag)
        ("StreamSpec", '{"camera": "a", "detections_wait": false}', False),
        ("StreamSpec", '{"camera": "a", "record": "true"}', False),
        ("StreamSpec", '{"camera": "a", "record": true, "record_keep": 3.0}', True),
        # a first box's coordinates too (were: true and "1" taken as 1)
        ("JobOptions", '{"mode": "single_target", "first_box": {"x": true, "y": 1, "w": 5, '
         '"h": 5}}', False),
    ],
)  # fmt: skip
def test_request_numbers_are_what_their_schema_says(model, body, taken) -> None:
    parse = {"JobOptions": JobOptions, "StreamSpec": StreamSpec}[model].model_validate_json
    if taken:
        parse(body)
    else:
        with pytest.raises(ValidationError):
            parse(body)


def test_the_documented_command_is_accepted() -> None:
    commands = documented_commands("api_fuzz.py")
    assert commands, "docs/benchmarks.md gives no command of benchmarks/api_fuzz.py"
    for command in commands:
        fuzz.arguments(command)
