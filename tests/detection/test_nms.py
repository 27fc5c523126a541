"""voc-release5 non-maximum suppression: overlap over the smaller (lower-scoring) box."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.detection.nms import box_iou, nms


@pytest.mark.parametrize(
    ("criterion", "kept"),
    [
        # a small box inside a large better one: IoU 0.16, but it is fully covered
        ("smaller", [0]),
        ("iou", [0, 1]),
    ],
)
def test_contained_box(criterion, kept):
    boxes = np.array([[0, 0, 50, 100], [10, 10, 20, 40]], float)
    assert box_iou(boxes[:1], boxes[1:])[0, 0] == pytest.approx(800 / 5000)
    assert nms(boxes, [2.0, 1.0], 0.5, criterion).tolist() == kept


def test_order_is_by_score_and_disjoint_boxes_survive():
    boxes = np.array([[0, 0, 10, 10], [100, 0, 10, 10], [2, 0, 10, 10]], float)
    # box 2 covers 80% of box 0's area but scores lower than box 0
    assert nms(boxes, [1.0, 3.0, 0.5], 0.5).tolist() == [1, 0]


def test_threshold_is_strict():
    # exactly half covered stays (voc-release5 suppresses when o > overlap)
    boxes = np.array([[0, 0, 10, 10], [5, 0, 10, 10]], float)
    assert nms(boxes, [2.0, 1.0], 0.5).tolist() == [0, 1]


def test_empty_and_bad_input():
    assert nms(np.zeros((0, 4)), np.zeros(0)).size == 0
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        nms(np.zeros((3, 3)), np.zeros(3))
    with pytest.raises(ValueError, match="scores"):
        nms(np.zeros((3, 4)), np.zeros(2))
