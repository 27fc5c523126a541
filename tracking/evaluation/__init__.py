"""Evaluation: the single-target metrics of the thesis (§5.1), exported here; the person
detectors' average precision and miss rate (:mod:`tracking.evaluation.detection`), MOTChallenge
result files (:mod:`tracking.evaluation.mot`) and HOTA (:mod:`tracking.evaluation.hota`).

The sequences evaluated on are read by :mod:`tracking.datasets` (OTB, MOTChallenge).
"""

from tracking.evaluation.metrics import (
    PRECISION_THRESHOLDS,
    SUCCESS_THRESHOLDS,
    SequenceResult,
    center_location_error,
    distance_precision,
    frames_per_second,
    iou,
    labeled_frames,
    overlap_precision,
    precision_curve,
    success_auc,
    success_curve,
    summarize,
)

__all__ = [
    "PRECISION_THRESHOLDS",
    "SUCCESS_THRESHOLDS",
    "SequenceResult",
    "center_location_error",
    "distance_precision",
    "frames_per_second",
    "iou",
    "labeled_frames",
    "overlap_precision",
    "precision_curve",
    "success_auc",
    "success_curve",
    "summarize",
]
