"""CNN person detectors on OpenVINO: Open Model Zoo SSDs and YOLOX heads (:class:`CnnDetector`)."""

from tracking.detection.cnn.config import CnnConfig
from tracking.detection.cnn.detector import KNOWN_CALIBRATIONS, CnnDetector
from tracking.detection.cnn.runtime import MODEL_SUFFIXES, CnnModelError, load_network

__all__ = [
    "KNOWN_CALIBRATIONS",
    "MODEL_SUFFIXES",
    "CnnConfig",
    "CnnDetector",
    "CnnModelError",
    "load_network",
]
