"""Shapes shared by every resource: boxes, points, errors."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from enum import StrEnum
from types import UnionType
from typing import Annotated, Any, ClassVar, Union, get_args, get_origin

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    GetJsonSchemaHandler,
    PlainSerializer,
    model_validator,
)
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import CoreSchema


def rounded(digits: int) -> PlainSerializer:
    """Write a float to JSON with ``digits`` decimals (Python values keep every bit).

    A full float takes 17 digits; results carry tens of coordinates per person and frame, so
    trajectories of an hour of video ran to hundreds of MB, mostly digits beyond what a
    tracker can tell.
    """
    return PlainSerializer(lambda value: round(value, digits), return_type=float, when_used="json")


Pixels = Annotated[float, rounded(2)]
"""Pixel coordinates, written to a hundredth of a pixel."""


class BoxModel(BaseModel):
    """An axis-aligned box in pixels: top-left corner ``(x, y)`` (0-based) and size ``(w, h)``.

    A box may reach past the frame's edges, for a person partly out of view (as MOTChallenge
    ground truth does): clip it to the frame before cropping the image.
    """

    # NaN and infinities would be written as null, which no reader of the JSON can take back
    model_config = ConfigDict(extra="forbid", title="Box", allow_inf_nan=False)

    x: Pixels = Field(description="Left edge in pixels, 0-based (0.01 px in results).")
    y: Pixels = Field(description="Top edge in pixels, 0-based (0.01 px in results).")
    w: Pixels = Field(gt=0, description="Width in pixels (0.01 px in results).")
    h: Pixels = Field(gt=0, description="Height in pixels (0.01 px in results).")


class FirstBox(BoxModel):
    """The box a single target is followed from: at least 1 pixel each way (the tracker's
    patch is sampled around it) and overlapping the frame."""

    # strict, as the options around it are: true or "1" is no coordinate
    model_config = ConfigDict(title="FirstBox", strict=True)

    # one sentence for 0, negative and sub-pixel sizes alike, as `vtrack track` words it
    w: float = Field(description="Width in pixels, at least 1.", json_schema_extra={"minimum": 1})
    h: float = Field(description="Height in pixels, at least 1.", json_schema_extra={"minimum": 1})

    @model_validator(mode="after")
    def _at_least_a_pixel(self) -> FirstBox:
        if not (self.w >= 1 and self.h >= 1):
            raise ValueError("width and height must be at least 1 pixel")
        return self


def _takes_int(annotation: object) -> bool:
    return annotation is int or (
        get_origin(annotation) in (Union, UnionType) and int in get_args(annotation)
    )


class RulesAcrossFields(BaseModel):
    """A request model whose validators enforce rules across its fields, stated in its JSON
    Schema too; its strict integer fields take a number without a fraction (``2.0``).

    :attr:`schema_rules` (JSON Schema subschemas, ``if``/``then`` mostly) go into the model's
    schema as ``allOf`` in validation mode, the schema of what is accepted, so
    that a client (or a generator of test requests) sees the rules the validators apply. Not in
    serialization mode: a record read back from storage skips the rules added since it was
    accepted (``from_stored``), so what the service returns need not follow them. A rule that
    JSON Schema cannot state (one number after another) is said in its field's description.
    """

    schema_rules: ClassVar[tuple[dict[str, Any], ...]] = ()

    @model_validator(mode="before")
    @classmethod
    def _whole_numbers(cls, data: Any) -> Any:
        # An integer field strict about types refuses 2.0, which JSON Schema's integer takes
        # (a number without a fraction; JavaScript writes no other): made an int here, before
        # the field's own validation, which keeps its schema (an annotated int would lose
        # its minimum and maximum to pydantic's schema of an optional).
        if not isinstance(data, dict):
            return data
        whole = {
            name: int(value)
            for name, value in data.items()
            if isinstance(value, float)
            and value.is_integer()
            and name in cls.model_fields
            and _takes_int(cls.model_fields[name].annotation)
        }
        return {**data, **whole} if whole else data

    @classmethod
    def __get_pydantic_json_schema__(
        cls, core_schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        schema = super().__get_pydantic_json_schema__(core_schema, handler)
        if handler.mode == "validation" and cls.schema_rules:
            target = handler.resolve_ref_schema(schema)
            target["allOf"] = [copy.deepcopy(rule) for rule in cls.schema_rules]
        return schema


def left_unset(*names: str) -> dict[str, Any]:
    """A JSON Schema saying that each of ``names`` is absent or null: left to its default."""
    return {"properties": {name: {"type": "null"} for name in names}}


def given(name: str) -> dict[str, Any]:
    """A JSON Schema (for ``if``) matching objects where ``name`` is present and not null."""
    return {"required": [name], "properties": {name: {"not": {"type": "null"}}}}


def equal(name: str, value: object) -> dict[str, Any]:
    """A JSON Schema (for ``if`` or ``then``) matching objects where ``name`` is ``value``."""
    return {"required": [name], "properties": {name: {"const": value}}}


class FailedCheck(BaseModel):
    """One check a request failed."""

    loc: list[str | int] = Field(
        description="Where: 'body', 'query' or 'options' (an upload's options part), then the "
        "path of the field in it, e.g. ['options', 'tracker', 'particles']."
    )
    msg: str = Field(description="What was wrong with it.")
    type: str = Field(
        description="The kind of failure, e.g. 'missing', 'extra_forbidden', "
        "'greater_than_equal', 'value_error' (a rule across fields)."
    )


class ErrorType(StrEnum):
    """The kind of an error answer: a code for programs to test, stable across releases (the
    sentence of ``detail`` may be reworded), each with one HTTP status.

    - ``validation_error`` (422): the body, the query or an upload's options part fails its
      schema; ``errors`` lists each failed check.
    - ``invalid_options`` (422): options the schema takes but the service cannot run (a model
      it lacks, a first box outside the frame, tracker options that contradict each other).
    - ``invalid_upload`` (422): an upload without its ``video`` file part, with a part it does
      not take or a part twice, or a malformed multipart body.
    - ``bad_request`` (400): a request that cannot be read (its client went away before its
      body ended).
    - ``invalid_range`` (400): a download's ``Range`` header that cannot be served.
    - ``unauthorized`` (401): no token, or not the one the service was configured with.
    - ``forbidden`` (403): a web page of another site, or a host name the service does not
      answer to.
    - ``not_found`` (404): no such path, job, stream, result or recording.
    - ``method_not_allowed`` (405): a method the path does not take (``Allow`` names those
      it takes).
    - ``timeout`` (408): the request's headers or body did not arrive in time.
    - ``conflict`` (409): not in a state for that: a job that has not succeeded, a camera
      tracked already.
    - ``payload_too_large`` (413): a body, upload or options part over its limit.
    - ``unsupported_media`` (415): an upload that is not ``multipart/form-data``.
    - ``invalid_video`` (415): an uploaded video that is empty or cannot be decoded.
    - ``range_not_satisfiable`` (416): a ``Range`` that starts beyond the end of the file.
    - ``headers_too_large`` (431): the request's line and headers are over their limit.
    - ``internal`` (500): an internal error; the service's log has the details.
    - ``busy`` (503): as many connections or event streams open as the service serves; try
      again after ``Retry-After``.
    - ``unavailable`` (503): what the request needs is not there now: the job database, live
      streams (Zenoh), or the service itself, which is stopping.
    - ``insufficient_storage`` (507): the data folder's disk is full or cannot be written.
    """

    validation_error = "validation_error"
    invalid_options = "invalid_options"
    invalid_upload = "invalid_upload"
    bad_request = "bad_request"
    invalid_range = "invalid_range"
    unauthorized = "unauthorized"
    forbidden = "forbidden"
    not_found = "not_found"
    method_not_allowed = "method_not_allowed"
    timeout = "timeout"
    conflict = "conflict"
    payload_too_large = "payload_too_large"
    unsupported_media = "unsupported_media"
    invalid_video = "invalid_video"
    range_not_satisfiable = "range_not_satisfiable"
    headers_too_large = "headers_too_large"
    internal = "internal"
    busy = "busy"
    unavailable = "unavailable"
    insufficient_storage = "insufficient_storage"


ERROR_STATUS: dict[ErrorType, int] = {
    ErrorType.validation_error: 422,
    ErrorType.invalid_options: 422,
    ErrorType.invalid_upload: 422,
    ErrorType.bad_request: 400,
    ErrorType.invalid_range: 400,
    ErrorType.unauthorized: 401,
    ErrorType.forbidden: 403,
    ErrorType.not_found: 404,
    ErrorType.method_not_allowed: 405,
    ErrorType.timeout: 408,
    ErrorType.conflict: 409,
    ErrorType.payload_too_large: 413,
    ErrorType.unsupported_media: 415,
    ErrorType.invalid_video: 415,
    ErrorType.range_not_satisfiable: 416,
    ErrorType.headers_too_large: 431,
    ErrorType.internal: 500,
    ErrorType.busy: 503,
    ErrorType.unavailable: 503,
    ErrorType.insufficient_storage: 507,
}
"""The HTTP status each :class:`ErrorType` is answered with."""


class ErrorResponse(BaseModel):
    """What every 4xx and 5xx answer carries: a code for programs, and a sentence saying what
    went wrong and what to do."""

    type: ErrorType = Field(description="The kind of error: a stable code to test in programs.")
    detail: str = Field(description="What went wrong, and what to change.")
    errors: list[FailedCheck] | None = Field(
        default=None, description="For validation errors (422): each failed check."
    )


def error_message(item: Mapping[str, Any]) -> str:
    """The message of one pydantic error (an item of ``ValidationError.errors()``) as users read
    it: without the "Value error, " that pydantic puts before our validators' own sentences."""
    return str(item["msg"]).removeprefix("Value error, ")
