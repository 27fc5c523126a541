"""The deformable part model engine (voc-release5 mixtures of star models)."""

from tracking.detection.dpm.config import DPM_TRACKING_CONFIG, DpmConfig
from tracking.detection.dpm.detector import (
    DEFAULT_DPM_CALIBRATION,
    KNOWN_CALIBRATIONS,
    KNOWN_CASCADES,
    DpmDetector,
)
from tracking.detection.dpm.model import (
    DpmComponent,
    DpmModel,
    FilterSymbol,
    ModelFileError,
    load_dpm_model,
)
from tracking.detection.dpm.parts import component_part_names, model_part_names

__all__ = [
    "DEFAULT_DPM_CALIBRATION",
    "DPM_TRACKING_CONFIG",
    "KNOWN_CALIBRATIONS",
    "KNOWN_CASCADES",
    "DpmComponent",
    "DpmConfig",
    "DpmDetector",
    "DpmModel",
    "FilterSymbol",
    "ModelFileError",
    "component_part_names",
    "load_dpm_model",
    "model_part_names",
]
