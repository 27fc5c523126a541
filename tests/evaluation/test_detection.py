"""Matching, average precision and log-average miss rate on cases worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.evaluation.detection import (
    average_precision,
    detection_curve,
    log_average_miss_rate,
    match_frame,
)

GT = np.array([[0, 0, 10, 20], [100, 0, 10, 20]], float)


def test_greedy_matching_by_score():
    boxes = np.array([[0, 0, 10, 20], [1, 0, 10, 20], [100, 0, 10, 20], [300, 0, 10, 20]], float)
    # the duplicate of person 0 (lower score) is a false positive; the far box too
    assert match_frame(boxes, [0.9, 0.8, 0.7, 0.6], GT).tolist() == [True, False, True, False]
    # if the duplicate scores higher, it takes the match instead
    assert match_frame(boxes, [0.8, 0.9, 0.7, 0.6], GT).tolist() == [False, True, True, False]


def test_a_detection_falls_back_to_its_next_best_untaken_person():
    # box 1's best person (IoU 0.82) is taken by box 0; its second (IoU 0.54) is free.
    # PASCAL VOC would count box 1 as a false positive.
    gt = np.array([[0, 0, 10, 20], [4, 0, 10, 20]], float)
    boxes = np.array([[0, 0, 10, 20], [1, 0, 10, 20]], float)
    assert match_frame(boxes, [0.9, 0.8], gt).tolist() == [True, True]


def test_perfect_detector():
    curve = detection_curve([(GT, [1.0, 0.9], GT), (GT[:1], [0.5], GT[:1])])
    assert average_precision(curve) == pytest.approx(1.0)
    assert log_average_miss_rate(curve) == pytest.approx(1e-10, rel=1e-6)


def test_average_precision_of_a_known_ranking():
    # ranking: TP, FP, TP, (one person never found): recall 1/3, 1/3, 2/3; precision 1, 1/2, 2/3
    # envelope: 1 on [0, 1/3], 2/3 on (1/3, 2/3] -> AP = 1/3 + 2/9
    gt = np.array([[0, 0, 10, 20], [100, 0, 10, 20], [200, 0, 10, 20]], float)
    boxes = np.array([[0, 0, 10, 20], [50, 0, 10, 20], [100, 0, 10, 20]], float)
    curve = detection_curve([(boxes, [0.9, 0.8, 0.7], gt)])
    assert average_precision(curve) == pytest.approx(1 / 3 + 2 / 9)


def test_log_average_miss_rate_of_a_flat_curve():
    # 10 frames, each with one person found and nothing else: the miss rate is 0 everywhere
    # except where the curve has not reached (all reference FPPI >= 0 are reached at once)
    frames = [(GT[:1], [1.0], GT[:2]) for _ in range(10)]  # half the people missed, no FP
    curve = detection_curve(frames)
    assert log_average_miss_rate(curve) == pytest.approx(0.5)


def test_average_precision_needs_ground_truth():
    with pytest.raises(ValueError, match="ground-truth"):
        average_precision(detection_curve([(GT, [1, 1], np.zeros((0, 4)))]))
