"""Live streams over Zenoh: the messages on the wire and the REST models that manage streams.

Key expressions, under a configurable prefix (``vtrack`` by default), for camera ``<camera>``:

- ``<prefix>/cameras/<camera>/frames`` (in): one sample per frame. The payload is a JPEG
  (encoding ``image/jpeg``), an H.264 access unit (``video/h264``: Annex B, one frame, no
  B-frames; tracked from the first key frame on) or raw pixels (any other encoding;
  ``width``, ``height`` and ``format`` in the attachment). The attachment is a
  :class:`FrameAttachment` as JSON.
- ``<prefix>/cameras/<camera>/detections`` (in, optional): :class:`UpstreamDetections` as JSON,
  matched to frames by sequence number; used instead of the service's detector when present.
- ``<prefix>/cameras/<camera>/tracks`` (out): one :class:`StreamTracksMessage` as JSON per
  processed frame.
- ``<prefix>/cameras/<camera>/tracks/ended`` (out): one :class:`StreamTracksEnded` as JSON when
  the tracks end (the camera went silent or started over, or its tracking stopped).
- ``<prefix>/trackers/<camera>/<instance>`` (liveliness token): present while an instance of
  the service tracks that camera.
- ``<prefix>/cameras/<camera>/tracks/current`` (queryable): answers with the latest
  :class:`StreamTracksMessage`.
"""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Any, Literal, TypedDict

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

from api_schemas.analytics import AnalyticsCounts, AnalyticsOptions
from api_schemas.common import RulesAcrossFields, equal
from api_schemas.jobs import DetectorOptions, PeopleTrackerOptions, field_name, stored
from api_schemas.tracks import FrameTracksMessage

CAMERA_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,63}$"
"""Camera names: one key-expression chunk (no ``/``, ``*``, ``$``, ``?`` or ``#``)."""

PREFIX_PATTERN = r"^[A-Za-z0-9_.\-]+(/[A-Za-z0-9_.\-]+)*$"
"""Key prefixes: one or more such chunks separated by ``/``."""

MAX_TIMESTAMP = 1e10
"""Latest capture time a frame may carry, in seconds since 1970 (the year 2286). Unix time in
milliseconds (1.7e12 in 2025) is beyond it, and so is every time whose nanoseconds do not fit
the unsigned 64 bits of an MCAP log time (1.8e10 s)."""


class PixelFormat(StrEnum):
    """Layout of a raw frame payload: 8 bits per channel, rows packed without padding."""

    rgb8 = "rgb8"
    bgr8 = "bgr8"
    mono8 = "mono8"

    @property
    def channels(self) -> int:
        return 1 if self is PixelFormat.mono8 else 3


class FrameAttachment(BaseModel):
    """The attachment (JSON) of every frame sample."""

    model_config = ConfigDict(extra="ignore")

    sequence: int = Field(ge=0, description="Frame counter of the camera, increasing by one.")
    timestamp: float = Field(
        ge=0,
        le=MAX_TIMESTAMP,
        allow_inf_nan=False,
        description="Capture time in seconds (Unix time recommended; not milliseconds). Tracks "
        "carry it back, and the tracker's motion model runs on it.",
    )
    width: int | None = Field(default=None, ge=1, le=16384, description="Raw frames only.")
    height: int | None = Field(default=None, ge=1, le=16384, description="Raw frames only.")
    format: PixelFormat | None = Field(default=None, description="Raw frames only.")


class UpstreamDetection(BaseModel):
    """One person found by an upstream detector, in pixels of the frame."""

    model_config = ConfigDict(extra="forbid")

    x: float = Field(allow_inf_nan=False)
    y: float = Field(allow_inf_nan=False)
    w: float = Field(gt=0, allow_inf_nan=False)
    h: float = Field(gt=0, allow_inf_nan=False)
    score: float = Field(
        allow_inf_nan=False,
        description="Detector confidence; clipped to [0, 1], it is taken as the probability "
        "that the box holds a person.",
    )


class UpstreamDetections(BaseModel):
    """The payload on the ``detections`` key: one frame's detections."""

    model_config = ConfigDict(extra="forbid")

    sequence: int = Field(ge=0, description="Sequence number of the frame they belong to.")
    detections: list[UpstreamDetection]


class StreamTracksMessage(FrameTracksMessage):
    """The payload on the ``tracks`` key: every person tracked in one frame of a stream.

    ``frame_index`` counts the frames this stream has tracked; ``timestamp`` is the frame's
    capture time as the camera stamped it.
    """

    model_config = ConfigDict(extra="forbid", title="StreamTracks")

    frame_index: int = Field(
        ge=0,
        description="Frames the stream's worker tracked before this one: it goes on when the "
        "tracks end and start over, and starts at 0 with a new stream or a new worker (after a "
        "restart of the service or of a worker that died).",
    )
    timestamp: float = Field(
        ge=0,
        description="The frame's capture time from its attachment, in seconds as the camera "
        "stamped it (Unix time from vtrack publish).",
    )
    camera: str
    sequence: int = Field(ge=0, description="The frame's sequence number from its attachment.")
    latency: float = Field(
        ge=0, description="Seconds from the frame's arrival at the tracker to this message."
    )
    frames_skipped: int = Field(
        ge=0,
        description="Frames skipped because tracking was behind (latest-first) that came "
        "between the previous message's frame and this one's: the gap between their sequence "
        "numbers, less one.",
    )
    detections: str = Field(
        description="Where this frame's detections came from: 'upstream' (the detections "
        "key) or 'service' (the service's own detector)."
    )


class StreamTracksEnded(BaseModel):
    """The payload on the ``tracks/ended`` key: every track of the stream ended at once.

    The tracks end when no frame came for ``end_tracks_after`` seconds, when the camera started
    over (a timestamp or sequence number that goes back) or changed resolution, when the
    tracker rejected a frame, and when tracking of the camera stops on this instance (the
    stream was deleted or stands by, the service shuts down). Their ids never come again; the
    next tracks message, if any, starts new tracks. A tracker that dies cannot say so: its
    liveliness token disappearing does.
    """

    model_config = ConfigDict(extra="forbid", title="StreamTracksEnded", allow_inf_nan=False)

    event: Literal["tracks_ended"] = "tracks_ended"
    camera: str
    reason: str = Field(description="Why they ended, in words.")
    sequence: int = Field(ge=0, description="Sequence number of the last frame tracked.")
    timestamp: float = Field(ge=0, description="Capture time of the last frame tracked.")
    track_ids: list[int] = Field(
        description="The ids of the last tracks message: the people tracked when they ended."
    )


# -- REST --------------------------------------------------------------------------------------


class StreamState(StrEnum):
    """Where a stream is in its life."""

    starting = "starting"
    """The worker process is starting and opening its Zenoh session."""
    waiting = "waiting"
    """Subscribed; no frame it can read has arrived yet (frames refused as malformed are
    counted and named in ``errors``)."""
    running = "running"
    """Frames are arriving and being tracked."""
    idle = "idle"
    """No frame for ``idle_after`` seconds; tracks end after ``end_tracks_after``."""
    standby = "standby"
    """Another service instance tracks the camera (its liveliness token says so); this one
    starts tracking when that token disappears. ``error`` names the other instance."""
    failed = "failed"
    """The worker keeps dying; see ``error``."""
    stopped = "stopped"
    """Stopped on request (``DELETE``); the record stays until deleted again."""


class _RecordingDefaults(TypedDict):
    record_segment: float
    record_keep: int
    record_images: Literal["h264", "jpeg"]


_RECORDING_DEFAULTS: _RecordingDefaults = {
    "record_segment": 300.0,
    "record_keep": 0,
    "record_images": "h264",
}
"""The recording options' defaults, all a stream that does not record may give."""


class StreamSpec(RulesAcrossFields):
    """A stream to track: the body of ``POST /v1/streams`` (or one entry of VTRACK_STREAMS).

    The recording options other than ``record`` are refused unless ``record`` is true or
    they are left at their defaults. Numbers and flags are strict, as a job's options are:
    ``false`` is no number of seconds, nor ``"yes"`` a flag.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    schema_rules = (
        {
            "if": {"not": equal("record", True)},
            "then": {
                "properties": {
                    name: {"const": value} for name, value in _RECORDING_DEFAULTS.items()
                }
            },
        },
    )

    camera: str = Field(
        pattern=CAMERA_PATTERN,
        description="Camera name: frames are read from <prefix>/cameras/<camera>/frames. "
        "It is also the stream's id.",
    )
    detector: DetectorOptions = Field(default_factory=DetectorOptions)
    tracker: PeopleTrackerOptions = Field(default_factory=PeopleTrackerOptions)
    analytics: AnalyticsOptions | None = Field(
        default=None,
        description="Zones and lines to watch: their events go out on "
        "<prefix>/cameras/<camera>/events and to the service's webhooks and MQTT broker. "
        "None: none.",
    )
    record: bool = Field(
        strict=True,
        default=False,
        description="Record frames and tracks to MCAP files, one per segment: a segment ends "
        "after record_segment seconds of stream time, when the tracks end and when the stream "
        "stops, and is downloadable from then on.",
    )
    record_segment: float = Field(
        strict=True,
        default=_RECORDING_DEFAULTS["record_segment"],
        ge=1,
        le=86400,
        description="Recording only (without record true, its default only): seconds of "
        "stream time (frame capture times) per recording file.",
    )
    record_keep: int = Field(
        strict=True,
        default=_RECORDING_DEFAULTS["record_keep"],
        ge=0,
        description="Recording only (without record true, its default only): finished "
        "recordings kept per stream, the oldest deleted first; 0 keeps all.",
    )
    record_images: Literal["h264", "jpeg"] = Field(
        default=_RECORDING_DEFAULTS["record_images"],
        description="Recording only (without record true, its default only): how recordings "
        "store the frames, as a job's mcap_images: 'h264' "
        "(foxglove.CompressedVideo) or 'jpeg' (foxglove.CompressedImage).",
    )
    idle_after: float = Field(
        strict=True, default=2.0, gt=0, le=600, description="Seconds without a frame before 'idle'."
    )
    end_tracks_after: float = Field(
        strict=True,
        default=10.0,
        gt=0,
        le=3600,
        description="Seconds without a frame before the tracks end; a camera that comes back "
        "later starts new tracks.",
    )
    detections_wait: float = Field(
        strict=True,
        default=0.05,
        ge=0,
        le=5,
        description="When the camera has an upstream detector (its detections key has spoken "
        "in the last 5 s), seconds to wait for a frame's detections before falling back to "
        "the service's detector.",
    )

    # Set without record, they would shape recordings that are never made: refused where they
    # were given, as a misspelt option is (streams stored before this rule read as they were).
    @field_validator("record_segment", "record_keep", "record_images")
    @classmethod
    def _with_record(cls, value: Any, info: ValidationInfo) -> Any:
        if stored(info):
            return value
        default = cls.model_fields[field_name(info)].get_default()
        if info.data.get("record") is False and value != default:
            raise ValueError("only with record: true (this stream records nothing)")
        return value

    @classmethod
    def from_stored(cls, text: str | bytes) -> StreamSpec:
        """A stream's spec as it was accepted, read back from storage: rules added since do
        not apply, so a stream an earlier version accepted still lists and starts."""
        return cls.model_validate_json(text, context={"stored": True})


class StreamCounters(BaseModel):
    """What a stream has seen since this service process started it (a worker that died and
    was restarted adds to them; a new service starts from zero)."""

    frames_in: int = Field(ge=0, description="Frame samples received.")
    frames_processed: int = Field(ge=0, description="Frames tracked (a tracks message each).")
    frames_skipped: int = Field(ge=0, description="Frames dropped because tracking was behind.")
    malformed: int = Field(
        ge=0, description="Samples (frames or detections) that could not be used."
    )
    detections_in: int = Field(ge=0, description="Upstream detection messages received.")
    detections_used: int = Field(ge=0, description="Frames tracked with upstream detections.")
    restarts: int = Field(
        ge=0, description="Times the tracker started over (camera idle, clock going back)."
    )


class StreamStatus(BaseModel):
    """The public view of a stream."""

    id: str
    camera: str
    state: StreamState
    created_at: datetime
    stopped_at: datetime | None = None
    counters: StreamCounters
    fps: float | None = Field(default=None, ge=0, description="Frames tracked per second, lately.")
    input_fps: float | None = Field(
        default=None,
        ge=0,
        description="Frames arriving per second, lately: beside fps, how far tracking keeps up "
        "with the camera (the difference is skipped, latest first).",
    )
    latency: float | None = Field(
        default=None, ge=0, description="Median processing latency of recent frames, seconds."
    )
    latency_p95: float | None = Field(default=None, ge=0)
    last_frame_at: datetime | None = Field(default=None, description="Arrival of the last frame.")
    errors: list[str] = Field(
        default_factory=list, description="The latest problems (bad payloads...), newest last."
    )
    error: str | None = Field(
        default=None,
        description="Why the stream failed, or stands by; after its worker died, why (until "
        "its successor has run for 30 s).",
    )
    worker_pid: int | None = None
    worker_starts: int = Field(ge=0, description="Worker processes started for this stream.")
    keys: dict[str, str] = Field(description="Zenoh key expressions of this stream.")
    recordings: list[str] = Field(
        default_factory=list,
        description="URLs of the finished MCAP recordings, oldest first (a recording is "
        "finished at the end of its segment, when the tracks end, and when the worker stops: "
        "DELETE, a service restart).",
    )
    detector: DetectorOptions | None = Field(
        default=None,
        description="The detector the stream's worker runs: its spec's with 'auto' resolved "
        "and the CNN's model named; None when the stream takes upstream detections only or "
        "the detector cannot run (see error).",
    )
    detector_warning: str | None = Field(
        default=None,
        description="What the stream loses with that detector (detector 'auto' without a CNN "
        "model: the embedded detector, and how to install the model).",
    )
    tracker: PeopleTrackerOptions | None = Field(
        default=None,
        description="The tracker options the stream's worker runs: its spec's with 'pose' and "
        "'reid' resolved (true or false) and their models named; None when they cannot run "
        "(see error).",
    )
    analytics: AnalyticsCounts | None = Field(
        default=None,
        description="The counts of the stream's zones and lines over the current run of its "
        "tracker (since it started, or the camera started over or changed resolution); None: "
        "it watches none, or has placed them on no frame yet.",
    )
    spec: StreamSpec


class StreamDetail(StreamStatus):
    """``GET /v1/streams/{id}``: the status and the current tracks."""

    tracks: StreamTracksMessage | None = Field(
        default=None, description="The latest tracks message (None before the first frame)."
    )


class StreamList(BaseModel):
    streams: list[StreamStatus]
