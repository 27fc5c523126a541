"""Job options to a tracking pipeline: what the service was configured with, which detector and
which networks (pose, re-identification) a job runs, the checks that refuse options that could
not run, and the pipeline built from them.

Both the upload jobs (:mod:`service.analysis`) and the live streams (:mod:`service.streams`)
build their pipelines here.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from api_schemas.jobs import DetectorOptions, JobOptions, PeopleTrackerOptions
from service.analytics import AnalyticsProblem, analytics_config
from service.frames import FrameSource, frame_size_problem
from service.models.catalog import CATALOG, model_path
from service.models.resolve import CNN_SETTING, POSE_SETTING, REID_SETTING, ModelSetting
from tracking.analytics import AnalyticsConfig
from tracking.correlation import PRESETS, CorrelationConfig
from tracking.detection.base import Detector
from tracking.detection.cnn import MODEL_SUFFIXES, CnnConfig, CnnDetector
from tracking.detection.dpm import DpmDetector
from tracking.detection.dpm.config import DPM_TRACKING_CONFIG
from tracking.detection.factory import make_detector
from tracking.detection.hog_people import HogPeopleConfig
from tracking.detection.pose import PoseConfig, PoseEstimator
from tracking.detection.reid import ReidConfig, ReidEmbedder
from tracking.people import PeopleTrackerConfig
from tracking.people.config import default_part_appearance
from tracking.pipeline import FramePipeline, PeoplePipeline, SingleTargetPipeline
from tracking.types import Box, box_problem

if TYPE_CHECKING:
    from service.settings import Settings

FETCH_HINT = (
    "run `vtrack models fetch --dir DIR` (it downloads Open Model Zoo's person-detection-0202 "
    "and the pose and re-identification networks, about 10 MB) and set VTRACK_MODELS_DIR=DIR"
)
"""How an operator installs the CNN detector's model."""

NO_CNN_WARNING = (
    "no CNN person model is installed, so detector 'auto' runs the embedded HOG detector, which "
    "finds fewer people (detection AP 0.80 / 0.64 against 0.92 / 0.89 with the CNN on "
    f"PETS09-S2L1 / TUD-Stadtmitte): to install it, {FETCH_HINT}"
)
"""The warning of a job whose detector 'auto' fell back to the embedded one."""


class OptionsError(ValueError):
    """Job options this service cannot run (unknown preset, no DPM or CNN model...); ``loc``,
    when one option is to blame, its path in the options (``("analytics", "zones", 0,
    "polygon")``)."""

    def __init__(
        self, message: str, loc: tuple[str | int, ...] | None = None, check: str | None = None
    ) -> None:
        super().__init__(message)
        self.loc = loc
        self.message = check or message
        """What was wrong with the option at ``loc``, without its path."""


@dataclass(frozen=True, slots=True)
class PipelineResources:
    """What the service was configured with (settings), not chosen per job.

    Attributes
    ----------
    dpm_model:
        The voc-release5 model of detector 'dpm' (VTRACK_DPM_MODEL).
    color_names:
        The w2c.mat Color Names table (VTRACK_COLOR_NAMES); None: the embedded one.
    models_dir:
        The folder of CNN models (VTRACK_MODELS_DIR) that a job's ``detector.model`` names.
    cnn_model:
        The network of detectors 'cnn' and 'auto' (VTRACK_CNN_MODEL resolved); None: none.
    pose_model:
        The body-keypoint network of ``tracker.pose`` (VTRACK_POSE_MODEL resolved); None: none.
    reid_model:
        The re-identification network of ``tracker.reid`` (VTRACK_REID_MODEL resolved); None:
        none.
    inference_threads:
        Threads of each CNN inference (0: OpenVINO's choice).

    A network file may be missing (a models folder without the default model): the options
    that ask for it are refused, those that leave it to the service run without it.
    """

    dpm_model: Path | None = None
    color_names: Path | None = None
    models_dir: Path | None = None
    cnn_model: Path | None = None
    pose_model: Path | None = None
    reid_model: Path | None = None
    inference_threads: int = 0

    @classmethod
    def from_settings(cls, settings: Settings) -> PipelineResources:
        return cls(
            dpm_model=settings.dpm_model,
            color_names=settings.color_names,
            models_dir=settings.models_dir,
            cnn_model=settings.cnn_model_path,
            pose_model=settings.pose_model_path,
            reid_model=settings.reid_model_path,
            inference_threads=settings.cnn_threads,
        )


NETWORK_OPTIONS = frozenset({"pose", "pose_model", "reid", "reid_model"})
"""Tracker options that choose networks (:func:`choose_networks`), not tracker parameters."""


def people_config(options: JobOptions, resources: PipelineResources) -> PeopleTrackerConfig:
    """The multi-person tracker's configuration: its defaults, the service's Color Names table
    and the job's ``tracker`` options (those that choose networks aside)."""
    base = PeopleTrackerConfig()
    if resources.color_names is not None:
        appearance = dataclasses.replace(
            base.appearance, color_names_path=str(resources.color_names)
        )
        base = dataclasses.replace(base, appearance=appearance)
    overrides = options.tracker.model_dump(exclude_none=True, exclude=set(NETWORK_OPTIONS))
    if "part_appearance" in overrides:  # the option switches the tracker's part trackers
        overrides["part_appearance"] = (
            default_part_appearance() if overrides["part_appearance"] else None
        )
    try:
        return dataclasses.replace(base, **overrides)
    except ValueError as error:
        raise OptionsError(f"tracker options are inconsistent: {error}") from None


# -- the detector --------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DetectorChoice:
    """The detector a job runs: its options with ``name`` resolved ('auto' -> 'cnn' or
    'default') and the CNN's ``model`` named, the network file, and what to tell the user."""

    options: DetectorOptions
    model_file: Path | None = None
    warning: str | None = None


def choose_detector(options: DetectorOptions, resources: PipelineResources) -> DetectorChoice:
    """Resolve ``options``: 'auto' runs the CNN when the service has its model, else the
    embedded detector with :data:`NO_CNN_WARNING`. Raises :class:`OptionsError` for a 'cnn' job
    whose model is not there."""
    if options.name == "auto":
        model = resources.cnn_model
        if model is None or not model.is_file():
            return DetectorChoice(
                options.model_copy(update={"name": "default"}), None, NO_CNN_WARNING
            )
        options = options.model_copy(update={"name": "cnn"})
    if options.name != "cnn":
        return DetectorChoice(options)
    path = model_file(CNN_OPTION, options.model, resources)
    return DetectorChoice(options.model_copy(update={"model": options.model or path.stem}), path)


@dataclass(frozen=True, slots=True)
class ModelOption:
    """A job option that runs a network of the service: what asks for it, its model option,
    the setting behind it, and what a job can do instead when the service has no model."""

    asks: str  # "detector 'cnn'", "tracker.pose true"
    option: str  # "detector.model"
    setting: ModelSetting
    instead: str  # "use detector 'default'"


CNN_OPTION = ModelOption("detector 'cnn'", "detector.model", CNN_SETTING, "use detector 'default'")
POSE_OPTION = ModelOption(
    "tracker.pose true", "tracker.pose_model", POSE_SETTING, "leave tracker.pose unset or false"
)
REID_OPTION = ModelOption(
    "tracker.reid true", "tracker.reid_model", REID_SETTING, "leave tracker.reid unset or false"
)


def model_file(kind: ModelOption, model: str | None, resources: PipelineResources) -> Path:
    """The network file a job option asks for: ``model`` in the models folder (a catalog name
    of the option's task or a path inside the folder), or, ``model`` None, the service's own
    model (the setting's). Cheap: the file is not read. Raises :class:`OptionsError` saying
    how to get it."""
    setting = kind.setting
    service_model = getattr(resources, setting.field)
    folder = resources.models_dir
    if model is None or (service_model is not None and model == service_model.stem):
        # the service's own model, also by the name the results give it (its file's stem)
        if service_model is None:
            if setting is CNN_SETTING:
                fix = FETCH_HINT
            else:
                fix = (
                    f"run `vtrack models fetch {setting.default} --dir DIR` and set "
                    f"VTRACK_MODELS_DIR=DIR (or {setting.variable} to the model's file)"
                )
            raise OptionsError(
                f"{kind.asks} needs {setting.what} model, and this service has none: its "
                f"operator can {fix}; or {kind.instead}"
            )
        path = service_model
    else:
        if folder is None:
            raise OptionsError(
                f"{kind.option} {model!r} names a file of the service's models folder, and "
                "this service has none: its operator can set VTRACK_MODELS_DIR (`vtrack models "
                "fetch --dir DIR` fills one)"
            )
        names = ", ".join(setting.catalog_names)
        if model in CATALOG and CATALOG[model].task != setting.task:
            raise OptionsError(
                f"{kind.option} {model!r} is a {CATALOG[model].task} model: {kind.asks} runs "
                f"{setting.what} model ({names})"
            )
        path = model_path(folder, model) if model in CATALOG else folder / model
        inside = path.resolve().is_relative_to(folder.resolve())
        if not inside or path.suffix.lower() not in MODEL_SUFFIXES:
            raise OptionsError(
                f"{kind.option} {model!r} is neither a model name ({names}) nor an .xml or "
                ".onnx file inside the service's models folder"
            )
    if not path.is_file():
        # the catalog name of the missing file, if it is a catalog model of the folder
        name = model if model in CATALOG else None
        if name is None and folder is not None:
            name = next((n for n in CATALOG if model_path(folder, n) == path), None)
        if name is not None and folder is not None:
            fetch = f"run `vtrack models fetch {name} --dir {folder}`"
        elif setting is CNN_SETTING:
            fetch = FETCH_HINT
        else:
            fetch = f"put it back ({setting.variable})"
        setting_named = "" if model is not None else f" ({setting.variable})"
        raise OptionsError(
            f"{kind.asks} needs the model {path}{setting_named}, which is not there: its "
            f"operator can {fetch}"
        )
    return path


# -- the pose and re-identification networks --------------------------------------------------


@dataclass(frozen=True, slots=True)
class NetworksChoice:
    """The networks a people job runs beside its detector: its tracker options with ``pose``
    and ``reid`` resolved (None -> true when the service has the model, else false) and the
    models that run named, and their files (None: off)."""

    tracker: PeopleTrackerOptions
    pose_file: Path | None = None
    reid_file: Path | None = None


def choose_networks(options: PeopleTrackerOptions, resources: PipelineResources) -> NetworksChoice:
    """Resolve ``options.pose`` and ``options.reid``: None runs the service's model when its
    file is there (else nothing, without a warning: the tracker does without), true runs it
    or the option's model, false nothing. Raises :class:`OptionsError` for a network asked for
    whose model is not there. Cheap (the files are not read)."""
    update: dict[str, object] = {}
    files: dict[str, Path | None] = {}
    for network, kind in (("pose", POSE_OPTION), ("reid", REID_OPTION)):
        wanted, model = getattr(options, network), getattr(options, f"{network}_model")
        if wanted is None and model is None:
            service_model = getattr(resources, kind.setting.field)
            wanted = service_model is not None and service_model.is_file()
        if wanted is False:
            update |= {network: False, f"{network}_model": None}
            files[network] = None
            continue
        path = model_file(kind, model, resources)
        update |= {network: True, f"{network}_model": model or path.stem}
        files[network] = path
    return NetworksChoice(options.model_copy(update=update), files["pose"], files["reid"])


MAX_ENLARGED_PIXELS = 7680 * 4320
"""The largest frame a detector is given after ``detector.upscale``: 8K. A 4K video at 4x
(15360x8640) took about 25 s and 3.6 GB per frame in one worker."""


def enlargement_problem(upscale: float | None, frame_size: tuple[int, int]) -> str | None:
    """Why ``detector.upscale`` cannot run on frames of ``frame_size`` (width, height): they
    would be enlarged beyond :data:`MAX_ENLARGED_PIXELS`; ``None`` when it can."""
    width, height = frame_size
    if upscale is None or width * height * upscale**2 <= MAX_ENLARGED_PIXELS:
        return None
    largest = math.floor(math.sqrt(MAX_ENLARGED_PIXELS / (width * height)) * 100) / 100
    return (
        f"detector.upscale {upscale:g} enlarges frames of {width}x{height} to "
        f"{round(width * upscale)}x{round(height * upscale)}, beyond the 7680x4320 the detector "
        f"takes: use at most {largest:g}, or leave it unset to let the detector choose"
    )


@dataclass(frozen=True, slots=True)
class JobPlan:
    """Job options checked once and resolved into what runs; :func:`build_pipeline` trusts it.

    Attributes
    ----------
    options:
        The options as they run, for the results to say so: detector 'auto' resolved and the
        CNN's model named, ``tracker.pose`` and ``tracker.reid`` true or false with their
        models named (single-target options as given).
    correlation:
        A single target's tracker: the preset's configuration with the service's Color Names
        table; None for people.
    first_box:
        A single target's first box; None for people.
    people:
        The multi-person tracker's configuration (:func:`people_config`, the box aspect left
        to a CNN's boxes); None for a single target.
    detector:
        The detector that runs; None for a single target, or for people whose detections are
        handed in.
    pose_file, reid_file:
        The pose and re-identification networks (None: off).
    dpm_model:
        The voc-release5 model of detector 'dpm'.
    inference_threads:
        Threads of each network's inference (0: OpenVINO's choice).
    analytics:
        The zones and lines watched, in pixels of the video (None: none, or a stream's whose
        frame size is not known yet).
    warnings:
        What to tell the user of the choices (the embedded detector standing in for the CNN).
    """

    options: JobOptions
    correlation: CorrelationConfig | None = None
    first_box: Box | None = None
    people: PeopleTrackerConfig | None = None
    detector: DetectorChoice | None = None
    pose_file: Path | None = None
    reid_file: Path | None = None
    dpm_model: Path | None = None
    inference_threads: int = 0
    analytics: AnalyticsConfig | None = None
    warnings: tuple[str, ...] = ()


def check_options(
    options: JobOptions,
    resources: PipelineResources,
    source: FrameSource | None = None,
    *,
    detect: bool = True,
) -> JobPlan:
    """Check ``options`` and resolve them into the plan of a run; cheap (loads no model).

    ``source``, the video, to check that its frames are large enough to track
    (:data:`~service.frames.MIN_SIDE`), a single target's first box, how large
    ``detector.upscale`` makes the frames, and that a frame is at or after ``start``.
    ``detect`` False, for people: the run takes each frame's detections (public detections,
    an upstream detector's) and the plan has no detector.

    Raises
    ------
    OptionsError
        For options that could not run here, saying why and what to change.
    """
    frame_size = None if source is None else (source.width, source.height)
    if frame_size is not None and (problem := frame_size_problem(*frame_size)):
        raise OptionsError(problem)
    if source is not None and (problem := source.start_problem(options.start)):
        raise OptionsError(problem)
    analytics = _analytics(options, frame_size)
    if options.mode == "single_target":
        return _single_target_plan(options, resources, frame_size, analytics)
    config = people_config(options, resources)
    networks = choose_networks(options.tracker, resources)
    options = options.model_copy(update={"tracker": networks.tracker})
    if frame_size is not None and (
        problem := enlargement_problem(options.detector.upscale, frame_size)
    ):
        raise OptionsError(problem)
    choice = None
    if detect:
        choice = choose_detector(options.detector, resources)
        options = options.model_copy(update={"detector": choice.options})
        if choice.options.name == "dpm":
            _check_dpm_model(resources.dpm_model)
        if choice.options.name == "cnn":
            # The CNN's boxes fit the people (the public detections and the HOG and DPM
            # detectors pad theirs, which the tracker's 0.41 aspect undoes): the tracks keep
            # their shape. Measured with its detections on PETS09-S2L1 and TUD-Stadtmitte,
            # HOTA 62.0 against 61.4 (3 seeds; docs/benchmarks-history.md).
            config = dataclasses.replace(config, box_aspect=None)
    return JobPlan(
        options=options,
        people=config,
        detector=choice,
        pose_file=networks.pose_file,
        reid_file=networks.reid_file,
        dpm_model=resources.dpm_model,
        inference_threads=resources.inference_threads,
        analytics=analytics,
        warnings=() if choice is None or choice.warning is None else (choice.warning,),
    )


def _analytics(options: JobOptions, frame_size: tuple[int, int] | None) -> AnalyticsConfig | None:
    """The zones and lines of ``options`` on frames of ``frame_size``; None without them, or
    when the frame size is not known yet (a stream's: its worker plans them at its first
    frame), after the checks that need no frame size."""
    if options.analytics is None:
        return None
    try:
        config = analytics_config(options.analytics, frame_size)
    except AnalyticsProblem as problem:
        raise OptionsError(str(problem), problem.loc, problem.message) from None
    return None if frame_size is None else config


def _single_target_plan(
    options: JobOptions,
    resources: PipelineResources,
    frame_size: tuple[int, int] | None,
    analytics: AnalyticsConfig | None,
) -> JobPlan:
    if options.preset is None or options.preset not in PRESETS:
        raise OptionsError(
            f"unknown preset {options.preset!r}: choose one of {', '.join(sorted(PRESETS))}"
        )
    b = options.first_box
    assert b is not None  # JobOptions guarantees it in this mode
    box = Box(b.x, b.y, b.w, b.h)
    if frame_size is not None and (problem := box_problem(box, (frame_size[1], frame_size[0]))):
        raise OptionsError(f"first_box {problem}")
    config = PRESETS[options.preset]
    if resources.color_names is not None:
        config = dataclasses.replace(config, color_names_path=str(resources.color_names))
    return JobPlan(options=options, correlation=config, first_box=box, analytics=analytics)


def _check_dpm_model(model: Path | None) -> None:
    if model is None:
        raise OptionsError(
            "detector 'dpm' needs a voc-release5 model, and this service has none: set "
            "VTRACK_DPM_MODEL to the .mat file, or use detector 'default'"
        )
    if not model.is_file():
        raise OptionsError(
            f"detector 'dpm' needs the model {model} (VTRACK_DPM_MODEL), which is no longer "
            "there: the service's operator must put it back, or use detector 'default'"
        )


def plan_detector(plan: JobPlan) -> Detector | None:
    """The detector of a people ``plan``, loaded (None when its detections are handed in)."""
    if plan.detector is None:
        return None
    options = plan.detector.options
    if options.name == "cnn":
        assert plan.detector.model_file is not None  # choose_detector names it
        cnn = CnnConfig(upscale=options.upscale, threads=plan.inference_threads)
        return CnnDetector.from_file(plan.detector.model_file, cnn)
    if options.name == "dpm":
        assert plan.dpm_model is not None  # check_options checked it
        dpm = dataclasses.replace(
            DPM_TRACKING_CONFIG,
            upscale=options.upscale or DPM_TRACKING_CONFIG.upscale,
            levels_per_octave=options.levels_per_octave or DPM_TRACKING_CONFIG.levels_per_octave,
        )
        # the model is known to be a DPM: make_detector would tell it by its .mat suffix
        return DpmDetector.from_file(plan.dpm_model, dpm)
    hog = HogPeopleConfig(upscale=options.upscale) if options.upscale else None
    return make_detector("default", hog)


def build_pipeline(plan: JobPlan) -> FramePipeline:
    """The pipeline of a checked ``plan`` (:func:`check_options`); loads its models.

    Raises
    ------
    ValueError
        A model file that does not load (corrupt, or not a network of its kind).
    """
    if plan.correlation is not None:
        assert plan.first_box is not None
        return SingleTargetPipeline(plan.first_box, plan.correlation)
    assert plan.people is not None
    threads = plan.inference_threads
    pose = reid = None
    if plan.pose_file is not None:
        pose = PoseEstimator.from_file(plan.pose_file, PoseConfig(threads=threads))
    if plan.reid_file is not None:
        reid = ReidEmbedder.from_file(plan.reid_file, ReidConfig(threads=threads))
    return PeoplePipeline(plan_detector(plan), plan.people, pose=pose, reid=reid)
