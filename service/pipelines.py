"""Job options to a tracking pipeline: what the service was configured with, which detector a
job runs, the checks that refuse options that could not run, and the pipeline built from them.

Both the upload jobs (:mod:`service.analysis`) and the live streams (:mod:`service.streams`)
build their pipelines here.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from api_schemas.jobs import DetectorOptions, JobOptions
from service.frames import FrameSource, frame_size_problem
from service.models.catalog import CATALOG, model_path
from tracking.correlation import PRESETS
from tracking.detection.base import Detector
from tracking.detection.cnn import MODEL_SUFFIXES, CnnConfig, CnnDetector
from tracking.detection.dpm import DpmDetector
from tracking.detection.dpm.config import DPM_TRACKING_CONFIG
from tracking.detection.factory import make_detector
from tracking.detection.hog_people import HogPeopleConfig
from tracking.people import PeopleTrackerConfig
from tracking.people.config import default_part_appearance
from tracking.pipeline import FramePipeline, PeoplePipeline, SingleTargetPipeline
from tracking.types import Box, box_problem

if TYPE_CHECKING:
    from service.settings import Settings

FETCH_HINT = (
    "run `vtrack models fetch --dir DIR` (it downloads Open Model Zoo's person-detection-0202, "
    "4 MB) and set VTRACK_MODELS_DIR=DIR"
)
"""How an operator installs the CNN detector's model."""

NO_CNN_WARNING = (
    "no CNN person model is installed, so detector 'auto' runs the embedded HOG detector, which "
    "finds fewer people (detection AP 0.80 / 0.64 against 0.92 / 0.89 with the CNN on "
    f"PETS09-S2L1 / TUD-Stadtmitte): to install it, {FETCH_HINT}"
)
"""The warning of a job whose detector 'auto' fell back to the embedded one."""


class OptionsError(ValueError):
    """Job options this service cannot run (unknown preset, no DPM or CNN model...)."""


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
    inference_threads:
        Threads of each CNN inference (0: OpenVINO's choice).
    """

    dpm_model: Path | None = None
    color_names: Path | None = None
    models_dir: Path | None = None
    cnn_model: Path | None = None
    inference_threads: int = 0

    @classmethod
    def from_settings(cls, settings: Settings) -> PipelineResources:
        return cls(
            dpm_model=settings.dpm_model,
            color_names=settings.color_names,
            models_dir=settings.models_dir,
            cnn_model=settings.cnn_model_path,
            inference_threads=settings.cnn_threads,
        )


def people_config(options: JobOptions, resources: PipelineResources) -> PeopleTrackerConfig:
    base = PeopleTrackerConfig()
    if resources.color_names is not None:
        appearance = dataclasses.replace(
            base.appearance, color_names_path=str(resources.color_names)
        )
        base = dataclasses.replace(base, appearance=appearance)
    overrides = options.tracker.model_dump(exclude_none=True)
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
    path = cnn_model_file(options.model, resources)
    return DetectorChoice(options.model_copy(update={"model": options.model or path.stem}), path)


def cnn_model_file(model: str | None, resources: PipelineResources) -> Path:
    """The network file of a 'cnn' job: ``model`` in the models folder (a catalog name or a
    path inside it), or the service's own model. Raises :class:`OptionsError` saying how to
    get it."""
    service_model = resources.cnn_model
    if model is None or (service_model is not None and model == service_model.stem):
        # the service's own model, also by the name the results give it (its file's stem)
        if resources.cnn_model is None:
            raise OptionsError(
                f"detector 'cnn' needs a CNN model, and this service has none: its operator can "
                f"{FETCH_HINT}; or use detector 'default'"
            )
        path = resources.cnn_model
    else:
        folder = resources.models_dir
        if folder is None:
            raise OptionsError(
                f"detector.model {model!r} names a file of the service's models folder, and "
                "this service has none: its operator can set VTRACK_MODELS_DIR (`vtrack models "
                "fetch --dir DIR` fills one)"
            )
        path = model_path(folder, model) if model in CATALOG else folder / model
        inside = path.resolve().is_relative_to(folder.resolve())
        if not inside or path.suffix.lower() not in MODEL_SUFFIXES:
            raise OptionsError(
                f"detector.model {model!r} is neither a model name ({', '.join(CATALOG)}) nor "
                "an .xml or .onnx file inside the service's models folder"
            )
    if not path.is_file():
        fetch = (
            f"run `vtrack models fetch {model} --dir {resources.models_dir}`"
            if model in CATALOG
            else FETCH_HINT
        )
        raise OptionsError(
            f"detector 'cnn' needs the model {path}, which is not there: its operator can {fetch}"
        )
    return path


def job_detector(options: DetectorOptions, resources: PipelineResources) -> Detector:
    """The detector ``options`` ask for ('auto' resolved as :func:`choose_detector` does)."""
    choice = choose_detector(options, resources)
    options = choice.options
    if options.name == "cnn":
        config = CnnConfig(upscale=options.upscale, threads=resources.inference_threads)
        return CnnDetector.from_file(choice.model_file, config)
    if options.name == "dpm":
        if resources.dpm_model is None:
            raise OptionsError(
                "detector 'dpm' needs a voc-release5 model, and this service has none: set "
                "VTRACK_DPM_MODEL to the .mat file, or use detector 'default'"
            )
        config = dataclasses.replace(
            DPM_TRACKING_CONFIG,
            upscale=options.upscale or DPM_TRACKING_CONFIG.upscale,
            levels_per_octave=options.levels_per_octave or DPM_TRACKING_CONFIG.levels_per_octave,
        )
        # the model is known to be a DPM: make_detector would tell it by its .mat suffix
        return DpmDetector.from_file(resources.dpm_model, config)
    config = HogPeopleConfig(upscale=options.upscale) if options.upscale else None
    return make_detector("default", config)


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


def check_options(
    options: JobOptions, resources: PipelineResources, source: FrameSource | None = None
) -> None:
    """Raise :class:`OptionsError` for options that could not run; cheap (loads no model).

    ``source``, the video, to check that its frames are large enough to track
    (:data:`~service.frames.MIN_SIDE`), a single target's first box, how large
    ``detector.upscale`` makes the frames, and that a frame is at or after ``start``.
    """
    frame_size = None if source is None else (source.width, source.height)
    if frame_size is not None and (problem := frame_size_problem(*frame_size)):
        raise OptionsError(problem)
    if source is not None and (problem := source.start_problem(options.start)):
        raise OptionsError(problem)
    if options.mode == "single_target":
        if options.preset not in PRESETS:
            raise OptionsError(
                f"unknown preset {options.preset!r}: choose one of {', '.join(sorted(PRESETS))}"
            )
        if frame_size is not None and options.first_box is not None:
            b = options.first_box
            if problem := box_problem(Box(b.x, b.y, b.w, b.h), (frame_size[1], frame_size[0])):
                raise OptionsError(f"first_box {problem}")
        return
    people_config(options, resources)
    if frame_size is not None and (
        problem := enlargement_problem(options.detector.upscale, frame_size)
    ):
        raise OptionsError(problem)
    if options.detector.name == "cnn":
        cnn_model_file(options.detector.model, resources)
    if options.detector.name == "dpm" and resources.dpm_model is None:
        raise OptionsError(
            "detector 'dpm' needs a voc-release5 model, and this service has none: set "
            "VTRACK_DPM_MODEL to the .mat file, or use detector 'default'"
        )
    if options.detector.name == "dpm" and not resources.dpm_model.is_file():
        raise OptionsError(
            f"detector 'dpm' needs the model {resources.dpm_model} (VTRACK_DPM_MODEL), which is "
            "no longer there: the service's operator must put it back, or use detector "
            "'default'"
        )


def build_pipeline(options: JobOptions, resources: PipelineResources) -> FramePipeline:
    """The pipeline the options ask for."""
    check_options(options, resources)
    if options.mode == "single_target":
        config = PRESETS[options.preset]
        if resources.color_names is not None:
            config = dataclasses.replace(config, color_names_path=str(resources.color_names))
        b = options.first_box
        assert b is not None  # JobOptions guarantees it in this mode
        return SingleTargetPipeline(Box(b.x, b.y, b.w, b.h), config)
    return PeoplePipeline(
        job_detector(options.detector, resources), people_config(options, resources)
    )
