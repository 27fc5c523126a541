"""pydantic v2 models of everything that crosses a process or network boundary
(docs/architecture.md §2).

No algorithm code. ``python -m api_schemas.export`` writes the JSON Schema of the public models
to ``api_schemas/schema.json``.
"""

from api_schemas.common import BoxModel, ErrorResponse, ErrorType, FailedCheck, FirstBox
from api_schemas.health import Health, Readiness
from api_schemas.jobs import (
    ALL_FORMATS,
    DetectorOptions,
    JobCreated,
    JobList,
    JobOptions,
    JobProgress,
    JobState,
    JobStatus,
    OutputFormat,
    PeopleTrackerOptions,
    ProgressEvent,
)
from api_schemas.streams import (
    FrameAttachment,
    PixelFormat,
    StreamCounters,
    StreamDetail,
    StreamList,
    StreamSpec,
    StreamState,
    StreamStatus,
    StreamTracksMessage,
    UpstreamDetection,
    UpstreamDetections,
)
from api_schemas.tracks import (
    FrameTracksMessage,
    PartState,
    TrackState,
    Trajectories,
    Trajectory,
    TrajectoryPoint,
    VideoInfo,
)

__all__ = [
    "ALL_FORMATS",
    "BoxModel",
    "DetectorOptions",
    "ErrorResponse",
    "ErrorType",
    "FailedCheck",
    "FirstBox",
    "FrameAttachment",
    "FrameTracksMessage",
    "Health",
    "JobCreated",
    "JobList",
    "JobOptions",
    "JobProgress",
    "JobState",
    "JobStatus",
    "OutputFormat",
    "PartState",
    "PeopleTrackerOptions",
    "PixelFormat",
    "ProgressEvent",
    "Readiness",
    "StreamCounters",
    "StreamDetail",
    "StreamList",
    "StreamSpec",
    "StreamState",
    "StreamStatus",
    "StreamTracksMessage",
    "TrackState",
    "Trajectories",
    "Trajectory",
    "TrajectoryPoint",
    "UpstreamDetection",
    "UpstreamDetections",
    "VideoInfo",
]
