"""Jobs: what a client sends to create one (options), and what it reads back (status, progress).

Schema families: :class:`JobOptions` is the creation request (the ``options`` part of the
upload), :class:`JobCreated` the acceptance, :class:`JobStatus` the public view with progress,
:class:`ProgressEvent` the live event of the progress stream.
"""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    ValidationInfo,
    field_validator,
    model_validator,
)

from api_schemas.analytics import AnalyticsOptions
from api_schemas.common import FirstBox, RulesAcrossFields, equal, given, left_unset


class OutputFormat(StrEnum):
    """Result formats a job can write."""

    json = "json"
    """The :class:`~api_schemas.tracks.Trajectories` model."""
    mcap = "mcap"
    """Foxglove-ready MCAP: images, annotations and track messages."""
    mot = "mot"
    """MOTChallenge text: ``frame,id,x,y,w,h,score,-1,-1,-1``."""
    mp4 = "mp4"
    """The video with boxes, ids, parts and trails drawn on it."""


ALL_FORMATS = tuple(OutputFormat)


class JobState(StrEnum):
    """Where a job is in its life."""

    queued = "queued"
    running = "running"
    succeeded = "succeeded"
    failed = "failed"
    cancelled = "cancelled"

    @property
    def finished(self) -> bool:
        return self in (JobState.succeeded, JobState.failed, JobState.cancelled)


MODEL_FILE_PATTERN = r"^[A-Za-z0-9_][A-Za-z0-9_./-]*$"
"""A model of the service's models folder, by catalog name or as a path inside the folder."""

# a path segment other than "..": empty, not starting with a dot, "." alone or before a
# character other than a dot, or ".." before at least one more character
_SEGMENT = (
    r"(?:[A-Za-z0-9_-][A-Za-z0-9_.-]*|\.(?:[A-Za-z0-9_-][A-Za-z0-9_.-]*)?|\.\.[A-Za-z0-9_.-]+)?"
)
MODEL_FILE_SCHEMA_PATTERN = rf"^[A-Za-z0-9_][A-Za-z0-9_.-]*(?:/{_SEGMENT})*$"
""":data:`MODEL_FILE_PATTERN` without a ``..`` segment, as the schema states it: the models
validate with the short pattern and refuse ``..`` on their own, saying why in words."""


def _inside_the_folder(value: str | None) -> str | None:
    if value is not None and ".." in value.split("/"):
        raise ValueError("must name a file inside the models folder, without '..'")
    return value


class DetectorOptions(RulesAcrossFields):
    """The person detector of a people-tracking job.

    Numbers and flags of every options model are strict: ``true`` is not a frame step nor
    ``"2"`` an upscale, and NaN or infinity is no number, so a client's type mistake gets a
    422 naming the field instead of a job that runs with a value nobody meant.
    """

    # examples of whole objects: a model's name alone, without its detector, breaks a rule
    model_config = ConfigDict(
        extra="forbid",
        allow_inf_nan=False,
        json_schema_extra={"examples": [{"name": "cnn", "model": "person-detection-0202"}]},
    )
    schema_rules = (
        {"if": given("levels_per_octave"), "then": equal("name", "dpm")},
        {"if": given("model"), "then": equal("name", "cnn")},
    )

    name: Literal["auto", "cnn", "default", "dpm"] = Field(
        default="auto",
        description="'auto' (default): 'cnn' when the service has a CNN model, else 'default' "
        "with a warning on the job that says how to install the model. 'cnn': a CNN person "
        "detector on OpenVINO (the model the service was configured with, or 'model'); it "
        "finds the most people. 'default': the embedded HOG people detector (no model file). "
        "'dpm': the deformable part model the service was configured with (VTRACK_DPM_MODEL), "
        "which also locates body parts. Results name the detector and model that ran.",
    )
    model: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        pattern=MODEL_FILE_PATTERN,
        json_schema_extra={"pattern": MODEL_FILE_SCHEMA_PATTERN},
        description="'cnn' only (name 'cnn' given with it): a model of the service's models "
        "folder (VTRACK_MODELS_DIR), by name as `vtrack models list` shows it "
        "(person-detection-0202, person-detection-0200, person-detection-retail-0013) or as a "
        "path inside that folder to an OpenVINO .xml or "
        "an .onnx file (yolox-nano/yolox_nano.onnx). None: the service's model "
        "(VTRACK_CNN_MODEL, by default person-detection-0202).",
    )
    upscale: float | None = Field(
        strict=True,
        default=None,
        gt=0,
        le=4,
        description="Enlarge frames by this factor before detecting. Embedded detector: "
        "people smaller than about 80 px need more than 1.5 (people 40-55 px tall need 2.0), "
        "at about twice the cost; None: by the frame's height (a portrait frame's width), 1.5 "
        "moved to keep the enlarged "
        "frame 720-1080 px high, at most 2.0 (360 px high: 2.0; 480-720 px: 1.5; 1080 px: "
        "1.0; 2160 px: 0.5). DPM: it finds people down to "
        "about 60 px / upscale tall; None: 1, or less for frames over 1080 px high (portrait: "
        "wide), which are "
        "searched at 1080 px (2160 px: 0.5, a quarter of the pixels). CNN: the network's input "
        "is the frame enlarged by this factor; None: the frame as it is when its height (a "
        "portrait frame's width) is 576-1080 px, else scaled into that range, at most 2x (360 "
        "px high: 1.6; 2160 px: 0.5). The enlarged frame may "
        "have at most 7680x4320 pixels (a 4K video: upscale 2 at most).",
    )
    levels_per_octave: int | None = Field(
        strict=True,
        default=None,
        ge=1,
        le=20,
        description="DPM only (name 'dpm' given with it): sizes of person searched per doubling "
        "of size (the feature pyramid's levels per octave). None: the model's own, 10 for "
        "voc-release5 models. Fewer levels search each frame faster and find slightly fewer "
        "people; what each costs and finds: docs/benchmarks.md.",
    )

    @field_validator("levels_per_octave")
    @classmethod
    def _of_the_dpm(cls, value: int | None, info: ValidationInfo) -> int | None:
        # the other detectors have no such pyramid: the option would do nothing there
        name = info.data.get("name")
        if value is not None and name not in (None, "dpm") and not stored(info):
            raise ValueError(
                f"only for detector 'dpm': detector '{name}' has no pyramid of this kind"
            )
        return value

    @field_validator("model")
    @classmethod
    def _of_the_cnn(cls, value: str | None, info: ValidationInfo) -> str | None:
        name = info.data.get("name")
        if value is not None and name not in (None, "cnn") and not stored(info):
            raise ValueError(
                f"only for detector 'cnn': detector '{name}' takes no model"
                + (" (set name to 'cnn' to choose the CNN's model)" if name == "auto" else "")
            )
        return _inside_the_folder(value)


class PeopleTrackerOptions(RulesAcrossFields):
    """Multi-person tracker parameters; each None keeps the tracker's default."""

    model_config = ConfigDict(
        extra="forbid",
        allow_inf_nan=False,
        json_schema_extra={
            "examples": [
                {
                    "pose": True,
                    "pose_model": "human-pose-estimation-0001",
                    "reid": True,
                    "reid_model": "person-reidentification-retail-0287",
                }
            ]
        },
    )
    schema_rules = (
        {"if": given("pose_model"), "then": equal("pose", True)},
        {"if": given("reid_model"), "then": equal("reid", True)},
    )

    particles: int | None = Field(
        strict=True, default=None, ge=2, le=1024, description="Particles per person."
    )
    full_detection_interval: float | None = Field(
        strict=True,
        default=None,
        ge=0,
        le=60,
        description="Seconds between full-frame detections; in between only regions around "
        "the tracks are searched, at a fraction of the cost. 0: every tracked frame is "
        "searched in full. Larger values track faster; how much, and what it does to the "
        "scores: docs/benchmarks.md.",
    )
    region_margin: float | None = Field(
        strict=True,
        default=None,
        ge=0,
        le=5,
        description="Margin, in person heights, of a searched region.",
    )
    confirm_hits: int | None = Field(
        strict=True,
        default=None,
        ge=1,
        le=30,
        description="Detections needed before a track is reported.",
    )
    max_missing: float | None = Field(
        strict=True,
        default=None,
        ge=0,
        le=60,
        description="Seconds without detection after which a track ends (tracker's default "
        "1.5); at most occluded_max_missing, given or its default (a rule across fields JSON "
        "Schema cannot state: refused with 422).",
    )
    occluded_max_missing: float | None = Field(
        strict=True,
        default=None,
        ge=0,
        le=120,
        description="The same while the person is occluded (tracker's default 3.0); at least "
        "max_missing, given or its default.",
    )
    report_missing: float | None = Field(
        strict=True,
        default=None,
        ge=0,
        le=60,
        description="Seconds a track is still reported, at its predicted box, while it lacks "
        "detections (0: not at all). 0.6 suits the 'dpm' detector (docs/benchmarks.md).",
    )
    report_occluded: bool | None = Field(
        strict=True,
        default=None,
        description="Report covered people (flagged occluded) without a detection.",
    )
    part_appearance: bool | None = Field(
        strict=True,
        default=None,
        description="Follow body parts with their own small correlation trackers.",
    )
    seed: int | None = Field(
        strict=True, default=None, ge=0, description="Seed of the particle filter."
    )
    pose: bool | None = Field(
        strict=True,
        default=None,
        description="Body keypoints: a pose network (Open Model Zoo's "
        "human-pose-estimation-0001) finds the 18 keypoints of every person in every frame "
        "(nose, neck, shoulders, elbows, wrists, hips, knees, ankles, eyes, ears), and the "
        "tracks' parts are those keypoints, named after them and measured where the frame "
        "showed them; off, the parts are the body model's (head, shoulders, hips, knees, feet), "
        "predicted from the box unless the 'dpm' detector or part_appearance places them. "
        "None (default): on when the service has the model (VTRACK_POSE_MODEL; /readyz says), "
        "off otherwise. true: required (a service without the model refuses the job). false: "
        "off. It costs time on every frame (docs/benchmarks.md; a 360 px video is fed at "
        "576 px). Results say whether it ran and which model.",
    )
    pose_model: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        pattern=MODEL_FILE_PATTERN,
        json_schema_extra={"pattern": MODEL_FILE_SCHEMA_PATTERN},
        description="With pose true only: a model of the service's models folder "
        "(VTRACK_MODELS_DIR), by name (human-pose-estimation-0001) or as a path inside that "
        "folder to an OpenVINO .xml or an .onnx file (an OpenPose network: 19 heatmaps and 38 "
        "part affinity fields). None: the service's model (VTRACK_POSE_MODEL, by default "
        "human-pose-estimation-0001).",
    )
    reid: bool | None = Field(
        strict=True,
        default=None,
        description="Re-identification: a network turns each detected person's crop into an "
        "appearance embedding, which tells people apart where they cross or meet (in place of "
        "clothing colours) and recognises a person who comes back after an occlusion or after "
        "leaving the view (remembered 30 s), so they keep their id. None (default): on when the "
        "service has the model (VTRACK_REID_MODEL; /readyz says), off otherwise. true: required "
        "(a service without the model refuses the job). false: off. It costs time per person "
        "and frame (docs/benchmarks.md). Results say whether it ran and which model.",
    )
    reid_model: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        pattern=MODEL_FILE_PATTERN,
        json_schema_extra={"pattern": MODEL_FILE_SCHEMA_PATTERN},
        description="With reid true only: a model of the service's models folder "
        "(VTRACK_MODELS_DIR), by name (person-reidentification-retail-0287; -0277, the most "
        "accurate and slowest; -0288, the smallest and fastest) or as a path inside that "
        "folder to an OpenVINO .xml or an .onnx file (one person crop in, one embedding out). "
        "None: the service's model (VTRACK_REID_MODEL, by default "
        "person-reidentification-retail-0287).",
    )

    @field_validator("pose_model", "reid_model")
    @classmethod
    def _with_its_network(cls, value: str | None, info: ValidationInfo) -> str | None:
        # as detector.model with 'cnn' only: a model asked for runs, or the job is refused
        network = field_name(info).removesuffix("_model")
        given = info.data.get(network, True)  # not there: its own error is enough
        if value is not None and given is not True and not stored(info):
            raise ValueError(
                f"only with {network} true, not {'unset' if given is None else 'false'}: "
                f"set {network} to true to run this model"
            )
        return _inside_the_folder(value)


DEFAULT_PRESET = "strcf_hog_cn"
"""The correlation preset of a single target whose options name none (the same as
``tracking.correlation.DEFAULT_PRESET``; this package does not import the algorithms)."""

FORMER_DEFAULT_PRESET = "hog_cn_scale"
"""The default before ``strcf_hog_cn`` (issue 77): the options of earlier jobs name it."""

_MODE_OF = {
    "first_box": ("single_target", "people are found by the detector"),
    "preset": ("single_target", "people are followed by the particle filter (tracker options)"),
    "detector": ("people", "a single target is followed from its first box by its preset"),
    "tracker": ("people", "a single target is followed from its first box by its preset"),
    "fill_gaps": ("people", "a single target is never dropped"),
}
"""The mode each mode-specific option belongs to, and why it means nothing in the other."""


_TRACKER_FIELDS = tuple(PeopleTrackerOptions.model_fields)

_DETECTOR_UNSET = {
    "properties": {
        "name": {"enum": ["auto", "default"]},
        **left_unset("model", "upscale", "levels_per_octave")["properties"],
    }
}
"""A detector left as it is by default (name 'auto', or 'default' as earlier jobs' options
have it, and nothing else set): what a single-target job may give."""


class JobOptions(RulesAcrossFields):
    """Options of a tracking job: the ``options`` JSON part of ``POST /v1/jobs``.

    Unknown fields are rejected, so a misspelt option fails loudly instead of being ignored.
    An option of the other mode is refused unless left at its default, and end must come
    after start (the one rule JSON Schema cannot state).
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    schema_rules = (
        {
            "if": equal("mode", "single_target"),
            "then": {
                "required": ["first_box"],
                "properties": {
                    "first_box": {"not": {"type": "null"}},
                    "detector": _DETECTOR_UNSET,
                    "tracker": left_unset(*_TRACKER_FIELDS),
                    "fill_gaps": {"const": 0},
                },
            },
            "else": {
                "properties": {
                    "first_box": {"type": "null"},
                    "preset": {"enum": [None, DEFAULT_PRESET, FORMER_DEFAULT_PRESET]},
                }
            },
        },
        {
            "if": {
                "required": ["formats"],
                "properties": {"formats": {"not": {"contains": {"const": "mcap"}}}},
            },
            "then": {"properties": {"mcap_images": {"const": "h264"}}},
        },
    )

    mode: Literal["people", "single_target"] = Field(
        default="people",
        description="'people': every person in view, with parts and occlusion; 'single_target':"
        " one object followed from first_box by a correlation tracker.",
    )
    first_box: FirstBox | None = Field(
        default=None,
        description="single_target only, and required there: the object's box in the first frame.",
    )
    preset: str | None = Field(
        default=None,
        pattern=r"^[a-z0-9_]+$",
        description="single_target only: correlation tracker preset (see `vtrack track --help`); "
        f"None: '{DEFAULT_PRESET}' in mode 'single_target', and stays None in mode 'people', "
        "which uses none.",
    )
    detector: DetectorOptions = Field(default_factory=DetectorOptions)
    tracker: PeopleTrackerOptions = Field(default_factory=PeopleTrackerOptions)
    formats: list[OutputFormat] = Field(
        default_factory=lambda: list(ALL_FORMATS),
        min_length=1,
        json_schema_extra={"uniqueItems": True},
        description="Results to write, each once. Each costs time: mcap and mp4 encode every "
        "frame.",
    )
    mcap_images: Literal["h264", "jpeg"] = Field(
        default="h264",
        description="How the mcap result stores the frames (other than 'h264' only when "
        "formats has mcap): 'h264' as foxglove.CompressedVideo "
        "(a key frame every second; far fewer bytes than JPEG, docs/benchmarks.md), 'jpeg' as "
        "foxglove.CompressedImage (each frame on its own, for tools that read images only).",
    )
    frame_step: int = Field(
        strict=True,
        default=1,
        ge=1,
        le=100,
        description="Track every frame_step-th frame (1: all). The tracker works in seconds, "
        "so it follows people across skipped frames; outputs hold the tracked frames only.",
    )
    start: float = Field(
        strict=True,
        default=0,
        ge=0,
        description="Seconds into the video where tracking begins: the first frame at or after "
        "this time is the first tracked (in mode 'single_target', the frame first_box is drawn "
        "on). Frames before it are read, not tracked. Results keep the video's own times and "
        "frame numbers (json timestamps and frame_index, mot frame numbers, mcap log times); "
        "the annotated mp4 starts at 0.",
    )
    end: float | None = Field(
        strict=True,
        default=None,
        gt=0,
        description="Seconds into the video where tracking stops, after start: frames at or "
        "after this time are not read. None: to the video's end.",
    )
    fill_gaps: float = Field(
        strict=True,
        default=0,
        ge=0,
        le=10,
        description="people only: seconds. When a person the tracker stopped reporting is "
        "reported again at most this long after the last frame they were seen in, the json and "
        "mot results also hold them in the tracked frames between, their box and parts moved "
        "linearly in time and marked interpolated (mcap and mp4 show the frames as tracked). "
        "0: off. 0.5-1 joins trajectories broken by brief occlusions; see docs/benchmarks.md "
        "for what it does to the scores.",
    )
    analytics: AnalyticsOptions | None = Field(
        default=None,
        description="Zones and lines to watch: the results then hold the events (line "
        "crossings, zones entered and left, dwells) and their counts, in total and per time "
        "bucket. None: none.",
    )

    labels: dict[
        Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_.:-]{1,64}$")],
        Annotated[str, StringConstraints(max_length=256)],
    ] = Field(
        default_factory=dict,
        max_length=20,
        # keys that do not match the pattern are refused, not free
        json_schema_extra={"additionalProperties": False},
        description="Your own names for the video, copied into its results (the json's options, "
        "the mcap's metadata) and listed with the job, for joining them with your records: "
        "the camera, the site, when the recording began... Up to 20; keys of 1-64 ASCII "
        "letters, digits and _ . : -, values up to 256 characters of any text.",
        examples=[{"camera": "entrance-2", "site": "store-042"}],
    )

    # An option of the other mode would be ignored: set to anything but its default, it is
    # refused where it was given (the error's loc names it), as a misspelt one is. Only given
    # fields are validated, and mode, declared first, before them.
    @field_validator("first_box", "preset", "detector", "tracker", "fill_gaps")
    @classmethod
    def _of_the_mode(cls, value: Any, info: ValidationInfo) -> Any:
        if stored(info):
            return value
        name = field_name(info)
        mode, reason = _MODE_OF[name]
        given = info.data.get("mode")
        default = cls.model_fields[name].get_default(call_default_factory=True)
        # the preset's default was a preset's name in every mode (hog_cn_scale, then
        # DEFAULT_PRESET), and the detector's 'default' before 'auto': options copied from an
        # earlier job's status still pass
        old_defaults = {
            "preset": (DEFAULT_PRESET, FORMER_DEFAULT_PRESET),
            "detector": (DetectorOptions(name="default"),),
        }.get(name, ())
        if given is not None and given != mode and value != default and value not in old_defaults:
            raise ValueError(f"only for mode '{mode}': {reason}")
        return value

    @field_validator("mcap_images")
    @classmethod
    def _with_the_mcap(cls, value: str, info: ValidationInfo) -> str:
        if stored(info):
            return value
        formats = info.data.get("formats")
        if value != "h264" and formats is not None and OutputFormat.mcap not in formats:
            raise ValueError("only with the mcap format, which formats leaves out")
        return value

    @classmethod
    def from_stored(cls, data: dict[str, Any]) -> JobOptions:
        """Options a job was accepted with, read back from storage: the refusals of options
        that would be ignored (added over time) do not apply, so a job an earlier version
        accepted still lists and runs as it did."""
        return cls.model_validate(data, context={"stored": True})

    @model_validator(mode="after")
    def _mode_fields(self) -> JobOptions:
        if self.mode == "single_target" and self.first_box is None:
            raise ValueError("mode 'single_target' needs first_box: the object's first box")
        if self.mode == "single_target" and self.preset is None:
            self.preset = DEFAULT_PRESET
        elif self.mode == "people":
            self.preset = None
        if len(set(self.formats)) != len(self.formats):
            raise ValueError("formats must not repeat a format")
        if self.end is not None and self.end <= self.start:
            raise ValueError(f"end ({self.end:g} s) must come after start ({self.start:g} s)")
        return self


def stored(info: ValidationInfo) -> bool:
    """Whether a model is being read back from storage (``context={'stored': True}``)."""
    return bool(info.context and info.context.get("stored"))


def field_name(info: ValidationInfo) -> str:
    """The name of the field a field validator is validating.

    Pydantic types it ``str | None`` because a model validator's ``info`` has none; a field
    validator's always has one.
    """
    assert info.field_name is not None, "a field validator's info names its field"
    return info.field_name


class JobProgress(BaseModel):
    """How far a job has come."""

    frames_done: int = Field(ge=0, description="Frames read so far.")
    frames_total: int | None = Field(
        default=None, ge=0, description="Frames the container announces (None: unknown)."
    )
    fps: float | None = Field(default=None, ge=0, description="Frames processed per second.")
    fraction: float | None = Field(default=None, ge=0, le=1, description="frames_done / total.")
    eta_seconds: float | None = Field(
        default=None,
        ge=0,
        description="Seconds until a running job has read its frames_total, at the rate it has "
        "read frames since it started (None: not running, total unknown, or no frame read "
        "yet). Writing the results' last bytes comes after.",
    )
    queued_ahead: int | None = Field(
        default=None,
        ge=0,
        description="For a queued job, the queued jobs that start before it (0: it starts as "
        "soon as a worker is free; jobs start oldest first). None once it has started.",
    )


class JobLinks(BaseModel):
    """Where to go next."""

    status: str = Field(description="This job's status (poll it).")
    events: str = Field(description="Server-sent events of this job's progress.")
    results: dict[str, str] = Field(
        default_factory=dict, description="Result URL per format, once the job has succeeded."
    )


class JobStatus(BaseModel):
    """The public view of a job."""

    id: str
    state: JobState
    created_at: datetime
    started_at: datetime | None = Field(
        default=None,
        description="When a worker started the job's latest attempt (an attempt that a stop "
        "of the service interrupted starts over: see attempts).",
    )
    finished_at: datetime | None = None
    progress: JobProgress
    error: str | None = Field(default=None, description="Why the job failed.")
    warnings: list[str] = Field(default_factory=list, description="Things worth knowing.")
    attempts: int = Field(ge=0, description="Times a worker started the job.")
    video_filename: str | None = None
    options: JobOptions
    links: JobLinks


class JobCreated(BaseModel):
    """The answer to an accepted upload (202)."""

    id: str
    state: JobState
    status_url: str = Field(description="Poll this for progress and results.")
    events_url: str = Field(description="Or follow this stream of server-sent events.")


class JobList(BaseModel):
    """Jobs, newest first, one page at a time."""

    jobs: list[JobStatus]
    next: str | None = Field(
        default=None,
        description="The next page (older jobs, same filter and limit); null on the last page.",
    )


class ProgressEvent(BaseModel):
    """One server-sent event of ``GET /v1/jobs/{id}/events`` (``data:`` line, JSON)."""

    id: str
    state: JobState
    progress: JobProgress
    error: str | None = None
