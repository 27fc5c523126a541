"""Person detection: the `Detector` contract, the DPM engine, the embedded default, outside boxes.

- :class:`DpmDetector` runs voc-release5 deformable part models (``inriaperson_final.mat``...)
  and gives part boxes and dense score maps;
- :class:`CnnDetector` runs CNN person detectors on OpenVINO (Open Model Zoo SSDs, YOLOX heads);
- :class:`PoseEstimator` finds body keypoints with an OpenPose-style network, and
  :class:`ReidEmbedder` embeds people's crops for re-identification;
- :class:`HogPeopleDetector` is the embedded fallback (OpenCV's HOG people detector, no file);
- :class:`MotDetections` and :class:`SubmittedDetections` bring detections from outside;
- :func:`make_detector` builds any of them from a name or a path.

Every detector returns :class:`Detections` (boxes, raw scores, calibrated probabilities, parts);
:class:`LogisticCalibration` maps scores to probabilities (``python -m devtools.calibrate``, from
a checkout, fits one).
"""

from tracking.detection.base import DenseScores, Detections, Detector
from tracking.detection.calibration import (
    CalibrationError,
    LogisticCalibration,
    calibration_path,
    fit_logistic,
    load_calibration,
)
from tracking.detection.cnn import CnnConfig, CnnDetector, CnnModelError
from tracking.detection.dpm import (
    DPM_TRACKING_CONFIG,
    DpmConfig,
    DpmDetector,
    DpmModel,
    ModelFileError,
    load_dpm_model,
)
from tracking.detection.external import (
    MotDetections,
    SubmittedDetections,
    detections_from_arrays,
)
from tracking.detection.factory import DETECTOR_NAMES, make_detector
from tracking.detection.hog_people import (
    HOG_PEOPLE_CALIBRATION,
    HogPeopleConfig,
    HogPeopleDetector,
)
from tracking.detection.nms import box_iou, nms
from tracking.detection.pose import PoseConfig, PoseEstimator, Poses
from tracking.detection.reid import ReidConfig, ReidEmbedder, cosine_similarity

__all__ = [
    "DETECTOR_NAMES",
    "DPM_TRACKING_CONFIG",
    "HOG_PEOPLE_CALIBRATION",
    "CalibrationError",
    "CnnConfig",
    "CnnDetector",
    "CnnModelError",
    "DenseScores",
    "Detections",
    "Detector",
    "DpmConfig",
    "DpmDetector",
    "DpmModel",
    "HogPeopleConfig",
    "HogPeopleDetector",
    "LogisticCalibration",
    "ModelFileError",
    "MotDetections",
    "PoseConfig",
    "PoseEstimator",
    "Poses",
    "ReidConfig",
    "ReidEmbedder",
    "SubmittedDetections",
    "box_iou",
    "calibration_path",
    "cosine_similarity",
    "detections_from_arrays",
    "fit_logistic",
    "load_calibration",
    "load_dpm_model",
    "make_detector",
    "nms",
]
