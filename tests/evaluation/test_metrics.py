"""Known answers for the tracking metrics of tracking.evaluation.metrics."""

from __future__ import annotations

import numpy as np
import pytest

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

GT = np.array(
    [
        [10.0, 20.0, 30.0, 40.0],
        [50.0, 60.0, 20.0, 10.0],
        [0.0, 0.0, 5.0, 5.0],
    ]
)


def test_identical_boxes_are_perfect() -> None:
    assert np.array_equal(center_location_error(GT, GT), np.zeros(3))
    assert np.array_equal(iou(GT, GT), np.ones(3))
    assert distance_precision(GT, GT) == 1.0
    assert overlap_precision(GT, GT) == 1.0
    # OTB counts overlap strictly above the threshold, so nothing passes at threshold 1:
    # a perfect tracker scores 20 of the 21 default thresholds.
    curve = success_curve(GT, GT)
    assert np.array_equal(curve, np.r_[np.ones(20), 0.0])
    assert success_auc(GT, GT) == pytest.approx(20 / 21)


@pytest.mark.parametrize(
    ("pred", "gt", "expected"),
    [
        # quarter overlap of two 10x10 boxes shifted diagonally by 5: 25 / (100 + 100 - 25)
        ([0, 0, 10, 10], [5, 5, 10, 10], 25 / 175),
        # half overlap, shifted along x only: 50 / 150
        ([0, 0, 10, 10], [5, 0, 10, 10], 1 / 3),
        # a 4x4 box inside a 10x10 one: 16 / 100
        ([2, 2, 4, 4], [0, 0, 10, 10], 0.16),
        # boxes sharing only an edge ([0, 10) and [10, 20)) do not overlap
        ([0, 0, 10, 10], [10, 0, 10, 10], 0.0),
        # disjoint boxes
        ([0, 0, 10, 10], [50, 50, 10, 10], 0.0),
        # different sizes, partial overlap: inter 6x4 = 24, union 80 + 60 - 24 = 116
        ([0, 0, 8, 10], [2, 6, 10, 6], 24 / 116),
        # a predicted box of zero width has no area and no overlap
        ([5, 5, 0, 10], [0, 0, 10, 10], 0.0),
    ],
)
def test_iou_hand_computed(pred: list[float], gt: list[float], expected: float) -> None:
    assert iou([pred], [gt])[0] == pytest.approx(expected)


@pytest.mark.parametrize(
    ("shift", "cle", "dp20"),
    [
        # 30 px to the right: every frame misses the 20 px threshold
        ((30.0, 0.0), 30.0, 0.0),
        # exactly 20 px (a 12-16-20 triangle): DP counts errors <= threshold
        ((12.0, 16.0), 20.0, 1.0),
        # just beyond 20 px
        ((0.0, 20.001), 20.001, 0.0),
    ],
)
def test_shifted_boxes(shift: tuple[float, float], cle: float, dp20: float) -> None:
    pred = GT.copy()
    pred[:, :2] += shift
    assert np.allclose(center_location_error(pred, GT), cle)
    assert distance_precision(pred, GT) == dp20


def test_centre_uses_size() -> None:
    # same top-left corner, twice the size: centres differ by half the extra size
    pred = np.array([[0.0, 0.0, 20.0, 40.0]])
    gt = np.array([[0.0, 0.0, 10.0, 10.0]])
    assert center_location_error(pred, gt)[0] == pytest.approx(np.hypot(5.0, 15.0))


def test_success_auc_of_constant_overlap() -> None:
    # every frame overlaps 1/3: thresholds 0, 0.05, ..., 0.30 pass (7 of 21), so AUC = 1/3
    pred = np.array([[0.0, 0.0, 10.0, 10.0]] * 4)
    gt = np.array([[5.0, 0.0, 10.0, 10.0]] * 4)
    assert success_auc(pred, gt) == pytest.approx(7 / 21)
    assert overlap_precision(pred, gt) == 0.0
    assert overlap_precision(pred, gt, threshold=0.3) == 1.0


def test_curves_agree_with_point_metrics() -> None:
    rng = np.random.default_rng(3)
    gt = np.column_stack([rng.uniform(0, 200, (50, 2)), rng.uniform(10, 60, (50, 2))])
    pred = gt + rng.normal(0, 15, gt.shape)
    precision = precision_curve(pred, gt)
    success = success_curve(pred, gt)
    assert precision.shape == PRECISION_THRESHOLDS.shape
    assert success.shape == SUCCESS_THRESHOLDS.shape
    assert np.all(np.diff(precision) >= 0) and np.all(np.diff(success) <= 0)
    assert precision[20] == distance_precision(pred, gt)
    assert success[10] == overlap_precision(pred, gt)  # threshold 0.5
    assert success_auc(pred, gt) == pytest.approx(success.mean())


@pytest.mark.parametrize(
    "unlabeled_row",
    [
        # OTB marks frames without a label in several ways; each is left out of every metric
        [0.0, 0.0, 0.0, 0.0],
        [np.nan, np.nan, np.nan, np.nan],
        [10.0, 10.0, -1.0, 20.0],
        [10.0, 10.0, 20.0, 0.0],
    ],
)
def test_unlabeled_frames_are_excluded(unlabeled_row: list[float]) -> None:
    gt = np.vstack([GT, unlabeled_row])
    pred = np.vstack([GT, [500.0, 500.0, 10.0, 10.0]])  # far off on the unlabeled frame
    assert labeled_frames(gt).tolist() == [True, True, True, False]
    assert np.isnan(center_location_error(pred, gt)[3])
    assert np.isnan(iou(pred, gt)[3])
    assert distance_precision(pred, gt) == 1.0
    assert overlap_precision(pred, gt) == 1.0
    assert success_auc(pred, gt) == pytest.approx(20 / 21)
    assert precision_curve(pred, gt)[0] == 1.0


def test_all_unlabeled_is_an_error() -> None:
    with pytest.raises(ValueError, match="no labeled frame"):
        distance_precision(GT, np.zeros((3, 4)))


def test_lost_prediction_counts_as_a_miss() -> None:
    pred = GT.copy()
    pred[1] = np.nan
    assert np.isinf(center_location_error(pred, GT)[1])
    assert iou(pred, GT)[1] == 0.0
    assert distance_precision(pred, GT) == pytest.approx(2 / 3)
    assert overlap_precision(pred, GT) == pytest.approx(2 / 3)


@pytest.mark.parametrize(
    ("pred", "gt", "message"),
    [
        # a single box is not an (N, 4) array
        (np.zeros(4), np.zeros((1, 4)), r"pred must have shape \(N, 4\), got \(4,\)"),
        # three coordinates per row
        (np.zeros((2, 4)), np.zeros((2, 3)), r"gt must have shape \(N, 4\), got \(2, 3\)"),
        # one row per frame on both sides
        (np.zeros((2, 4)), np.zeros((3, 4)), "got 2 and 3 rows"),
    ],
)
def test_shape_validation(pred: np.ndarray, gt: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        iou(pred, gt)


@pytest.mark.parametrize(
    ("seconds", "fps"),
    [
        # two frames in one second
        ([0.5, 0.5], 2.0),
        # 100 frames of 10 ms
        ([0.01] * 100, 100.0),
        # a slow initialisation weighs in: 4 frames in 0.4 s
        ([0.25, 0.05, 0.05, 0.05], 10.0),
    ],
)
def test_frames_per_second(seconds: list[float], fps: float) -> None:
    assert frames_per_second(seconds) == pytest.approx(fps)


@pytest.mark.parametrize(
    "seconds",
    [
        [],  # no frame
        [0.0, 0.0],  # no time measured
        [0.1, -0.1],  # negative time
        [[0.1, 0.1]],  # not 1-D
    ],
)
def test_frames_per_second_rejects(seconds: list) -> None:
    with pytest.raises(ValueError):
        frames_per_second(seconds)


def test_summarize() -> None:
    pred = GT.copy()
    pred[2, 0] += 30.0  # one frame 30 px off, and without overlap (box 5 px wide)
    result = SequenceResult("seq", "tracker", pred, [0.1, 0.05, 0.05])
    figures = summarize(result, GT)
    assert figures["dp"] == pytest.approx(2 / 3)
    assert figures["op"] == pytest.approx(2 / 3)
    assert figures["auc"] == pytest.approx(2 / 3 * 20 / 21)
    assert figures["cle"] == pytest.approx(10.0)
    assert figures["fps"] == pytest.approx(15.0)
    assert figures["frames"] == 3


def test_sequence_result_checks_lengths() -> None:
    with pytest.raises(ValueError, match=r"seconds must have shape \(3,\)"):
        SequenceResult("seq", "tracker", GT, [0.1, 0.1])
