"""Export the JSON Schema of the public models: ``python -m api_schemas.export [--check]``.

Writes ``api_schemas/schema.json``: one object whose ``$defs`` hold every public model (with
the models they refer to). A test fails when the file in the repository is out of date.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pydantic import BaseModel
from pydantic.json_schema import models_json_schema

from api_schemas.analytics import AnalyticsResult, CameraEvent
from api_schemas.common import ErrorResponse
from api_schemas.health import Health, Readiness
from api_schemas.jobs import JobCreated, JobList, JobOptions, JobStatus, ProgressEvent
from api_schemas.streams import (
    FrameAttachment,
    StreamDetail,
    StreamList,
    StreamSpec,
    StreamStatus,
    StreamTracksEnded,
    StreamTracksMessage,
    UpstreamDetections,
)
from api_schemas.tracks import FrameTracksMessage, Trajectories

PUBLIC_MODELS: tuple[type[BaseModel], ...] = (
    JobOptions,
    JobCreated,
    JobStatus,
    JobList,
    ProgressEvent,
    Trajectories,
    FrameTracksMessage,
    StreamSpec,
    StreamStatus,
    StreamDetail,
    StreamList,
    FrameAttachment,
    UpstreamDetections,
    StreamTracksMessage,
    StreamTracksEnded,
    CameraEvent,
    AnalyticsResult,
    ErrorResponse,
    Health,
    Readiness,
)
SCHEMA_PATH = Path(__file__).with_name("schema.json")


def build_schema() -> dict:
    """The JSON Schema document of :data:`PUBLIC_MODELS` (validation mode: what is accepted)."""
    _, document = models_json_schema(
        [(model, "validation") for model in PUBLIC_MODELS],
        title="visual-tracking API models",
    )
    return document


def model_schema(model: type[BaseModel]) -> dict:
    """A self-contained JSON Schema of one model (its own ``$defs``), for message channels."""
    return model.model_json_schema()


def render() -> str:
    return json.dumps(build_schema(), indent=2, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m api_schemas.export", description=__doc__)
    parser.add_argument("--out", type=Path, default=SCHEMA_PATH, help="where to write")
    parser.add_argument(
        "--check", action="store_true", help="exit 1 if the file differs instead of writing it"
    )
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        current = args.out.read_text() if args.out.is_file() else ""
        if current != text:
            print(f"{args.out} is out of date: run python -m api_schemas.export", file=sys.stderr)
            return 1
        return 0
    args.out.write_text(text)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
