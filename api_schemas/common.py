"""Shapes shared by every resource: boxes, points, errors."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, PlainSerializer, model_validator


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

    model_config = ConfigDict(title="FirstBox")

    # one sentence for 0, negative and sub-pixel sizes alike, as `vtrack track` words it
    w: float = Field(description="Width in pixels, at least 1.", json_schema_extra={"minimum": 1})
    h: float = Field(description="Height in pixels, at least 1.", json_schema_extra={"minimum": 1})

    @model_validator(mode="after")
    def _at_least_a_pixel(self) -> FirstBox:
        if not (self.w >= 1 and self.h >= 1):
            raise ValueError("width and height must be at least 1 pixel")
        return self


class ErrorResponse(BaseModel):
    """What every 4xx and 5xx answer carries: a sentence saying what went wrong and what to do."""

    detail: str = Field(description="What went wrong, and what to change.")
    errors: list[dict[str, Any]] | None = Field(
        default=None, description="For validation errors: each failed check (location, message)."
    )


def error_message(item: Mapping[str, Any]) -> str:
    """The message of one pydantic error (an item of ``ValidationError.errors()``) as users read
    it: without the "Value error, " that pydantic puts before our validators' own sentences."""
    return str(item["msg"]).removeprefix("Value error, ")
