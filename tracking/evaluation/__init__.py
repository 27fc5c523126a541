"""Single-target evaluation: OTB sequences and the metrics of the thesis (§5.1)."""

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
from tracking.evaluation.otb import (
    OtbSequence,
    SequenceError,
    find_otb_sequences,
    load_otb_sequence,
    parse_ground_truth,
    read_frame,
)

__all__ = [
    "PRECISION_THRESHOLDS",
    "SUCCESS_THRESHOLDS",
    "OtbSequence",
    "SequenceError",
    "SequenceResult",
    "center_location_error",
    "distance_precision",
    "find_otb_sequences",
    "frames_per_second",
    "iou",
    "labeled_frames",
    "load_otb_sequence",
    "overlap_precision",
    "parse_ground_truth",
    "precision_curve",
    "read_frame",
    "success_auc",
    "success_curve",
    "summarize",
]
