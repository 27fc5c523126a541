"""Trajectories and per-frame track messages: what the pipeline found, at the service edge.

``tracking`` returns plain dataclasses (:mod:`tracking.tracks`); the service converts them to
these models when it writes results or publishes messages.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from api_schemas.analytics import AnalyticsResult
from api_schemas.common import BoxModel, Pixels, rounded
from api_schemas.jobs import JobOptions

INTERPOLATED = (
    "True when the tracker did not report the object in this frame: the estimate was filled "
    "in afterwards, linearly in time between the frames before and after the gap (job option "
    "fill_gaps)."
)


Score = Annotated[float, rounded(4)]
Seconds = Annotated[float, rounded(6)]

SCORE = (
    "Confidence in the box. People: the probability that the box holds a person, a running "
    "average of the calibrated detector scores of the detections the track matched. A single "
    "target: the peak of the correlation filter's response, clipped to 0-1 (how well the patch "
    "matches the learned appearance; it falls when the target is covered or lost, though not "
    "reliably once the filter has drifted onto another object). Its scale depends on the "
    "preset and the target (0.3-1 on the frame the filter was learned from): compare it "
    "between the frames of one track, not between presets. Written to 4 decimals."
)
OCCLUDED = (
    "True while the tracker judges the object covered by a nearer one. The occluder can be a "
    "track that is not reported in that frame (not yet confirmed, or without a detection), so "
    "it need not appear among the frame's tracks. Always false for a single target."
)


class PartState(BaseModel):
    """One body part of a tracked person in one frame."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    name: str = Field(
        description="Stable part name, e.g. 'head', 'left_shoulder'. Left and right are the "
        "image's: a left_ part lies on the left of the image (the person's own right when they "
        "face the camera), since a part model cannot tell which way a person faces."
    )
    x: Pixels = Field(description="Centre of the part, pixels (0.01 px).")
    y: Pixels = Field(description="Centre of the part, pixels (0.01 px).")
    box: BoxModel | None = Field(
        default=None, description="The part's box, when the model has one."
    )
    visible: bool = Field(
        description="False when the part lies inside the box of a nearer person covering its "
        "own (so an occluded person's parts outside the occluder stay visible) or out of the "
        "frame: its position is less reliable. Whether the position was measured "
        "or predicted is 'measured'; a part can be measured and not visible (the 'dpm' "
        "detector placed it on a person judged occluded)."
    )
    measured: bool = Field(
        default=False,
        description="True when this frame's image placed the part (the 'dpm' detector's part "
        "placement, or the part's own tracker); false when the position is the body model's "
        "prediction from the box: always with the default detector, which finds no parts, "
        "unless the tracker option part_appearance follows them.",
    )


class TrackState(BaseModel):
    """One tracked object in one frame."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    track_id: int = Field(
        ge=0,
        description="Stable id of the object within one video or stream: people are numbered "
        "from 1 in the order the tracker confirms them (a stream's numbers jump after a restart "
        "of its worker); a single target is 1.",
    )
    box: BoxModel
    score: Score = Field(ge=0, le=1, description=SCORE)
    occluded: bool = Field(description=OCCLUDED)
    parts: list[PartState] = Field(default_factory=list)
    interpolated: bool = Field(default=False, description=INTERPOLATED)


class FrameTracksMessage(BaseModel):
    """Everything tracked in one frame: the message of the MCAP ``/tracks`` channel."""

    model_config = ConfigDict(extra="forbid", title="FrameTracks", allow_inf_nan=False)

    frame_index: int = Field(ge=0, description="0-based index of the frame in its video.")
    timestamp: Seconds = Field(
        ge=0, description="Capture time in seconds (video position), to the microsecond."
    )
    tracks: list[TrackState]


class TrajectoryPoint(BaseModel):
    """One object in one frame, as part of its trajectory."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    frame_index: int = Field(ge=0, description="0-based index of the frame in the video.")
    timestamp: Seconds = Field(
        ge=0, description="Capture time in seconds (video position), to the microsecond."
    )
    box: BoxModel
    score: Score = Field(ge=0, le=1, description=SCORE)
    occluded: bool = Field(description=OCCLUDED)
    parts: list[PartState] = Field(default_factory=list)
    interpolated: bool = Field(default=False, description=INTERPOLATED)


class Trajectory(BaseModel):
    """One object through the video: the frames where the tracker reported it, in order."""

    model_config = ConfigDict(extra="forbid")

    track_id: int = Field(ge=0)
    frames: list[TrajectoryPoint]


class VideoInfo(BaseModel):
    """The analysed video."""

    model_config = ConfigDict(extra="forbid")

    filename: str | None = Field(default=None, description="Name of the uploaded file.")
    width: int = Field(ge=1)
    height: int = Field(ge=1)
    fps: float | None = Field(
        default=None,
        description="Frame rate the container (or an image folder's seqinfo.ini or --fps) "
        "declares; null when it declares none: frames without a time of their own are then "
        "stamped 25 per second, with a warning.",
    )
    frames_announced: int = Field(
        ge=0, description="Frame count the container declares; 0 when it declares none."
    )
    frames_read: int = Field(
        ge=0,
        description="Frames that decoded up to end, skipped ones and those before start "
        "included (fewer when truncated).",
    )
    frame_step: int = Field(ge=1, description="Every frame_step-th frame was tracked.")
    start: float = Field(
        default=0, ge=0, description="Seconds into the video where tracking began (options.start)."
    )
    end: float | None = Field(
        default=None,
        description="Seconds into the video where tracking stopped (options.end); None: at the "
        "video's end.",
    )
    pixel_aspect_ratio: float = Field(
        default=1.0,
        gt=0,
        description=(
            "Width over height of one stored pixel, as the container states it (12/11 for PAL "
            "D1 recorders, 1 for square pixels). Boxes and part points are in stored pixels: "
            "multiply x and w by it for the picture as a player shows it."
        ),
    )


class Trajectories(BaseModel):
    """The JSON result of a job: one trajectory per tracked object."""

    model_config = ConfigDict(extra="forbid")

    vtrack_version: str = Field(
        description="Version of visual-tracking that wrote it (`vtrack --version`); fields may "
        "be added in a later version, and a changed or removed field comes with a new major "
        "version."
    )
    job_id: str | None = Field(default=None, description="The job that produced it (None: CLI).")
    options: JobOptions = Field(
        description="The options it was tracked with, defaults filled in (with the job's labels)."
    )
    warnings: list[str] = Field(
        default_factory=list,
        description="What the run told of the video (damaged frames, a truncated file...): the "
        "job's warnings.",
    )
    mode: Literal["people", "single_target"]
    video: VideoInfo
    part_names: list[str] = Field(description="Names of the parts the tracks carry.")
    skeleton: list[tuple[str, str]] = Field(
        default_factory=list,
        description="Pairs of part names joined by a limb, for drawing (e.g. ['neck', "
        "'right_shoulder']); empty when the tracks carry no parts.",
    )
    frames_processed: int = Field(ge=0, description="Frames the tracker saw.")
    analytics: AnalyticsResult | None = Field(
        default=None, description="The events and counts of the job's zones and lines (None: none)."
    )
    tracks: list[Trajectory]
