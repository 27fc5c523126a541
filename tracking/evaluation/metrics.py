"""Single-target tracking metrics: centre error, distance and overlap precision, success AUC, fps.

The thesis measures its trackers with the protocol and code of the OTB benchmark (Danelljan 2013,
§5.1; Wu, Lim, Yang, "Online Object Tracking: A Benchmark", CVPR 2013), with the metrics of
§5.1.1:

- centre location error (CLE): Euclidean distance between the estimated and the true target
  centre, in pixels;
- distance precision (DP): the share of frames whose CLE is within a threshold (20 px);
- overlap precision (OP): the share of frames whose box overlap
  ``|r_est ∩ r_gt| / |r_est ∪ r_gt|`` exceeds a threshold (0.5, the PASCAL criterion);
- speed in frames per second.

The success plot of Wu et al. sweeps the overlap threshold over ``0, 0.05, ..., 1`` and ranks
trackers by the mean of that curve (the "area under the curve", AUC). Overlap counts strictly
above the threshold, as in the OTB code, so a perfect tracker scores 20/21 at the default
thresholds (nothing exceeds an overlap of 1).

Boxes are ``(N, 4)`` arrays of ``x, y, w, h`` (top-left corner and size, pixels), one row per
frame. Ground-truth rows that are NaN or have a non-positive width or height mark unlabeled frames
(the OTB convention) and are left out of every metric: their per-frame values are NaN and they
count neither in the numerator nor in the denominator of a share. A prediction that is not finite
counts as a miss (infinite CLE, zero overlap).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_DISTANCE_THRESHOLD = 20.0
DEFAULT_OVERLAP_THRESHOLD = 0.5
PRECISION_THRESHOLDS = np.arange(0, 51, dtype=np.float64)
SUCCESS_THRESHOLDS = np.linspace(0.0, 1.0, 21)


def _boxes(boxes: object, name: str) -> np.ndarray:
    array = np.asarray(boxes, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 4:
        raise ValueError(f"{name} must have shape (N, 4), got {array.shape}")
    return array


def _pair(pred: object, gt: object) -> tuple[np.ndarray, np.ndarray]:
    p, g = _boxes(pred, "pred"), _boxes(gt, "gt")
    if p.shape[0] != g.shape[0]:
        raise ValueError(
            f"pred and gt must have one row per frame each, got {p.shape[0]} and {g.shape[0]} rows"
        )
    return p, g


def _labeled_values(values: np.ndarray) -> np.ndarray:
    """Drop the NaN entries (unlabeled frames); at least one must remain."""
    kept = values[~np.isnan(values)]
    if kept.size == 0:
        raise ValueError("the ground truth has no labeled frame (all rows NaN or of size <= 0)")
    return kept


def labeled_frames(gt: object) -> np.ndarray:
    """``(N,)`` bool: frames whose ground truth is finite with positive width and height."""
    g = _boxes(gt, "gt")
    return np.isfinite(g).all(axis=1) & (g[:, 2] > 0) & (g[:, 3] > 0)


def center_location_error(pred: object, gt: object) -> np.ndarray:
    """Centre location error per frame (thesis §5.1.1), in pixels.

    Parameters
    ----------
    pred, gt:
        ``(N, 4)`` boxes ``x, y, w, h``.

    Returns
    -------
    np.ndarray
        ``(N,)`` float64: ``||c_pred - c_gt||`` with ``c = (x + w/2, y + h/2)``; NaN on unlabeled
        frames, ``inf`` where the prediction is not finite.
    """
    p, g = _pair(pred, gt)
    with np.errstate(invalid="ignore"):
        delta = (p[:, :2] + p[:, 2:] / 2.0) - (g[:, :2] + g[:, 2:] / 2.0)
        error = np.hypot(delta[:, 0], delta[:, 1])
    error[~np.isfinite(error)] = np.inf
    error[~labeled_frames(g)] = np.nan
    return error


def iou(pred: object, gt: object) -> np.ndarray:
    """Overlap (intersection over union) per frame: ``|r_pred ∩ r_gt| / |r_pred ∪ r_gt|``.

    Boxes are continuous rectangles ``[x, x + w) x [y, y + h)`` (thesis §5.1.1; PASCAL VOC).

    Returns
    -------
    np.ndarray
        ``(N,)`` float64 in ``[0, 1]``; NaN on unlabeled frames, 0 where the prediction is not
        finite or has no area.
    """
    p, g = _pair(pred, gt)
    with np.errstate(invalid="ignore"):
        # intersection width/height: min of right edges - max of left edges, floored at 0
        lo = np.maximum(p[:, :2], g[:, :2])
        hi = np.minimum(p[:, :2] + p[:, 2:], g[:, :2] + g[:, 2:])
        inter = np.prod(np.clip(hi - lo, 0.0, None), axis=1)
        area_p = np.prod(np.clip(p[:, 2:], 0.0, None), axis=1)
        area_g = np.prod(np.clip(g[:, 2:], 0.0, None), axis=1)
        overlap = inter / (area_p + area_g - inter)  # union > 0 wherever gt is labeled
    overlap[~np.isfinite(overlap)] = 0.0
    overlap[~labeled_frames(g)] = np.nan
    return overlap


def distance_precision(
    pred: object, gt: object, threshold: float = DEFAULT_DISTANCE_THRESHOLD
) -> float:
    """Share of labeled frames with centre error ``<= threshold`` pixels (DP, thesis §5.1.1)."""
    error = _labeled_values(center_location_error(pred, gt))
    return float(np.mean(error <= threshold))


def precision_curve(
    pred: object, gt: object, thresholds: np.ndarray = PRECISION_THRESHOLDS
) -> np.ndarray:
    """Distance precision at each threshold (the OTB precision plot): ``(T,)`` in ``[0, 1]``."""
    error = _labeled_values(center_location_error(pred, gt))
    limits = np.asarray(thresholds, dtype=np.float64)
    return np.mean(error[:, None] <= limits[None, :], axis=0)


def overlap_precision(
    pred: object, gt: object, threshold: float = DEFAULT_OVERLAP_THRESHOLD
) -> float:
    """Share of labeled frames with overlap ``> threshold`` (OP, thesis §5.1.1; OTB uses ``>``)."""
    overlap = _labeled_values(iou(pred, gt))
    return float(np.mean(overlap > threshold))


def success_curve(
    pred: object, gt: object, thresholds: np.ndarray = SUCCESS_THRESHOLDS
) -> np.ndarray:
    """Overlap precision at each threshold (the OTB success plot): ``(T,)`` in ``[0, 1]``."""
    overlap = _labeled_values(iou(pred, gt))
    limits = np.asarray(thresholds, dtype=np.float64)
    return np.mean(overlap[:, None] > limits[None, :], axis=0)


def success_auc(pred: object, gt: object, thresholds: np.ndarray = SUCCESS_THRESHOLDS) -> float:
    """Area under the success curve, taken as its mean over the thresholds (OTB convention).

    With the default 21 thresholds ``0, 0.05, ..., 1`` a perfect tracker scores 20/21: the curve
    is 0 at threshold 1 because overlap counts strictly above the threshold.
    """
    return float(np.mean(success_curve(pred, gt, thresholds)))


def frames_per_second(seconds_per_frame: object) -> float:
    """Speed: frames divided by the total time spent on them (thesis §5.1.1).

    Parameters
    ----------
    seconds_per_frame:
        ``(N,)`` time spent by the tracker on each frame, in seconds.

    Raises
    ------
    ValueError
        If the times are not a non-empty 1-D array of finite non-negative values with a positive
        sum.
    """
    seconds = np.asarray(seconds_per_frame, dtype=np.float64)
    if seconds.ndim != 1 or seconds.size == 0:
        raise ValueError(f"seconds_per_frame must have shape (N,) with N > 0, got {seconds.shape}")
    if not np.isfinite(seconds).all() or (seconds < 0).any():
        raise ValueError("seconds_per_frame must be finite and non-negative")
    total = float(seconds.sum())
    if total <= 0.0:
        raise ValueError("seconds_per_frame sums to 0: no time was measured")
    return seconds.size / total


@dataclass(frozen=True, slots=True, eq=False)
class SequenceResult:
    """What one tracker produced on one sequence.

    Attributes
    ----------
    name:
        Sequence name.
    tracker:
        Tracker (variant) name.
    boxes:
        ``(N, 4)`` float64 estimated boxes ``x, y, w, h``, one per frame; the first is the
        initial box.
    seconds:
        ``(N,)`` float64 tracker time per frame in seconds (initialisation for the first frame,
        one update for each later frame; reading frames is not included).
    """

    name: str
    tracker: str
    boxes: np.ndarray
    seconds: np.ndarray

    def __post_init__(self) -> None:
        boxes = _boxes(self.boxes, "boxes")
        seconds = np.asarray(self.seconds, dtype=np.float64)
        if seconds.shape != (boxes.shape[0],):
            raise ValueError(
                f"seconds must have shape ({boxes.shape[0]},) to match boxes, got {seconds.shape}"
            )
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "seconds", seconds)


def summarize(result: SequenceResult, gt: object) -> dict[str, float]:
    """The figures of one run: ``dp`` (DP at 20 px), ``op`` (OP at 0.5), ``auc`` (success AUC),
    ``cle`` (mean CLE over labeled frames, px), ``fps`` and ``frames`` (frame count)."""
    p, g = _pair(result.boxes, gt)
    return {
        "dp": distance_precision(p, g),
        "op": overlap_precision(p, g),
        "auc": success_auc(p, g),
        "cle": float(np.mean(_labeled_values(center_location_error(p, g)))),
        "fps": frames_per_second(result.seconds),
        "frames": p.shape[0],
    }
