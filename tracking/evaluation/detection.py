"""Detection metrics: matching to ground truth, average precision, miss rate against FPPI.

Matching (one frame): detections are taken in decreasing score; each is a true positive when its
best intersection-over-union with a ground-truth box not yet matched is at least 0.5 (that box
is then matched), a false positive otherwise. This is the PASCAL VOC criterion (Everingham et
al., IJCV 2010, §4.4) with one difference: a detection whose best ground truth is already taken
may still match its next-best untaken one (as Dollár et al.'s Caltech evaluation does).

Average precision (:func:`average_precision`): all detections of all frames sorted by score,
precision and recall after each, the precision made monotone from the right (the "precision
envelope"), and the area under that step curve (VOC 2010+ "all points" AP, not the 11-point
VOC 2007 variant).

Log-average miss rate (:func:`log_average_miss_rate`): Dollár, Wojek, Schiele, Perona,
"Pedestrian Detection: An Evaluation of the State of the Art", PAMI 34(4), 2012: the miss rate
``1 - recall`` against false positives per image (FPPI); the miss rate is read at nine FPPI
values evenly spaced in log space over ``[1e-2, 1e0]`` (the lowest miss rate reached at or below
each; 1 where the curve has not started) and their geometric mean reported.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from tracking.detection.nms import box_iou

__all__ = [
    "FPPI_REFERENCE_POINTS",
    "DetectionCurve",
    "average_precision",
    "detection_curve",
    "log_average_miss_rate",
    "match_frame",
]

FPPI_REFERENCE_POINTS = np.logspace(-2.0, 0.0, 9)
"""Dollár et al.'s reference FPPI values: ``10^-2, 10^-1.75, ..., 10^0``."""


def match_frame(
    boxes: object, scores: object, gt_boxes: object, iou_threshold: float = 0.5
) -> np.ndarray:
    """Which detections of one frame are true positives (greedy by score, see module doc).

    Parameters
    ----------
    boxes:
        ``(N, 4)`` detections ``x, y, w, h``.
    scores:
        ``(N,)`` their scores.
    gt_boxes:
        ``(M, 4)`` ground-truth boxes.
    iou_threshold:
        Minimum IoU of a match.

    Returns
    -------
    np.ndarray
        ``(N,)`` bool, in the order of ``boxes``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    gt = np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 4)
    if scores.shape[0] != boxes.shape[0]:
        raise ValueError(f"scores must have shape ({boxes.shape[0]},), got {scores.shape}")
    positive = np.zeros(boxes.shape[0], dtype=bool)
    if boxes.shape[0] == 0 or gt.shape[0] == 0:
        return positive
    iou = box_iou(boxes, gt)
    taken = np.zeros(gt.shape[0], dtype=bool)
    for i in np.argsort(-scores, kind="stable"):
        candidates = np.where(taken, -1.0, iou[i])
        j = int(np.argmax(candidates))
        if candidates[j] >= iou_threshold:
            taken[j] = True
            positive[i] = True
    return positive


@dataclass(frozen=True, slots=True)
class DetectionCurve:
    """Cumulative counts over all frames, by decreasing score.

    Attributes
    ----------
    scores:
        ``(K,)`` detection scores, decreasing.
    true_positives, false_positives:
        ``(K,)`` cumulative counts after each detection.
    num_gt:
        Ground-truth boxes over all frames.
    num_frames:
        Frames evaluated.
    """

    scores: np.ndarray
    true_positives: np.ndarray
    false_positives: np.ndarray
    num_gt: int
    num_frames: int

    @property
    def recall(self) -> np.ndarray:
        return self.true_positives / max(self.num_gt, 1)

    @property
    def precision(self) -> np.ndarray:
        return self.true_positives / np.maximum(self.true_positives + self.false_positives, 1)

    @property
    def miss_rate(self) -> np.ndarray:
        return 1.0 - self.recall

    @property
    def fppi(self) -> np.ndarray:
        return self.false_positives / max(self.num_frames, 1)


def detection_curve(
    frames: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]], iou_threshold: float = 0.5
) -> DetectionCurve:
    """Match every frame and accumulate the precision/recall bookkeeping.

    Parameters
    ----------
    frames:
        Per frame ``(boxes (N, 4), scores (N,), gt_boxes (M, 4))``.
    iou_threshold:
        Minimum IoU of a match.
    """
    all_scores, all_tp = [], []
    num_gt = num_frames = 0
    for boxes, scores, gt in frames:
        num_frames += 1
        gt = np.asarray(gt, dtype=np.float64).reshape(-1, 4)
        num_gt += gt.shape[0]
        scores = np.asarray(scores, dtype=np.float64).reshape(-1)
        all_scores.append(scores)
        all_tp.append(match_frame(boxes, scores, gt, iou_threshold))
    scores = np.concatenate(all_scores) if all_scores else np.zeros(0)
    tp = np.concatenate(all_tp) if all_tp else np.zeros(0, dtype=bool)
    order = np.argsort(-scores, kind="stable")
    tp = tp[order]
    return DetectionCurve(
        scores=scores[order],
        true_positives=np.cumsum(tp),
        false_positives=np.cumsum(~tp),
        num_gt=num_gt,
        num_frames=num_frames,
    )


def average_precision(curve: DetectionCurve) -> float:
    """Area under the precision envelope against recall ("all points" VOC AP)."""
    if curve.num_gt == 0:
        raise ValueError("average precision needs at least one ground-truth box")
    recall = np.concatenate([[0.0], curve.recall, [curve.recall[-1] if curve.recall.size else 0]])
    precision = np.concatenate([[1.0], curve.precision, [0.0]])
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    return float(np.sum(np.diff(recall) * envelope[1:]))


def log_average_miss_rate(curve: DetectionCurve, reference: np.ndarray | None = None) -> float:
    """Dollár et al.'s log-average miss rate over FPPI ``1e-2 .. 1e0`` (lower is better)."""
    reference = FPPI_REFERENCE_POINTS if reference is None else np.asarray(reference)
    fppi, miss = curve.fppi, curve.miss_rate
    samples = np.ones(reference.size)
    for i, ref in enumerate(reference):
        reached = np.flatnonzero(fppi <= ref)
        if reached.size:
            samples[i] = miss[reached[-1]]
    return float(np.exp(np.mean(np.log(np.maximum(samples, 1e-10)))))
