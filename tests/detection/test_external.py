"""MOTChallenge det.txt reading (0-based boxes) and detections handed in by the caller."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.datasets.mot import MotFormatError, MotSequence, read_mot_rows
from tracking.detection.calibration import LogisticCalibration
from tracking.detection.external import (
    MotDetections,
    SubmittedDetections,
    detections_from_arrays,
)
from tracking.types import Box


def test_public_detections_of_pets(pets):
    dets = MotDetections.from_file(pets.detections_file)
    first = dets.for_frame(0)  # rows with frame == 1
    # det.txt line 1: 1,-1,243.00,218.00,45.00,90.00,0.87006,-1,-1,-1 (1-based pixels)
    assert first.boxes[0].tolist() == [242.0, 217.0, 45.0, 90.0]
    assert first.scores[0] == pytest.approx(0.87006)
    assert first.probabilities[0] == pytest.approx(0.87006)  # conf clipped to [0, 1]
    assert first.parts.shape == (len(first), 0, 4)
    assert sum(len(dets.for_frame(i)) for i in range(dets.num_frames)) == 5434
    assert dets.num_frames == 795
    assert dets.dense_scores(None, Box(0, 0, 10, 10)) is None


def test_scaled_detections_are_those_of_smaller_frames():
    parts = np.array([[[10.0, 20.0, 4.0, 8.0], [np.nan] * 4]])
    found = detections_from_arrays(
        [[100.0, 40.0, 20.0, 60.0]], [0.9], parts=parts, part_names=("head", "left_foot")
    )
    half = found.scaled(0.5)
    assert half.boxes.tolist() == [[50.0, 20.0, 10.0, 30.0]]
    np.testing.assert_array_equal(half.parts, parts * 0.5)  # a missing part stays missing
    assert half.probabilities.tolist() == [0.9] and half.part_names == found.part_names


def test_detect_walks_through_the_frames_and_seek_jumps(pets):
    dets = MotDetections.from_file(pets.detections_file)
    a, b = dets.detect(None), dets.detect(None)
    np.testing.assert_array_equal(a.boxes, dets.for_frame(0).boxes)
    np.testing.assert_array_equal(b.boxes, dets.for_frame(1).boxes)
    dets.seek(0)
    np.testing.assert_array_equal(dets.detect(None).boxes, a.boxes)
    region = Box(240, 240, 40, 40)  # around the first box's centre (264.5, 262)
    dets.seek(0)
    inside = dets.detect_region(None, region)
    assert len(inside) == 1 and inside.boxes[0, 0] == 242.0


def test_calibration_and_confidence_filter(tmp_path):
    path = tmp_path / "det.txt"
    path.write_text("1,-1,10,20,30,60,0.9,-1,-1,-1\n1,-1,50,20,30,60,0.3,-1,-1,-1\n")
    calibrated = MotDetections.from_file(path, calibration=LogisticCalibration(10.0, -5.0))
    np.testing.assert_allclose(
        calibrated.for_frame(0).probabilities, 1 / (1 + np.exp(-(10 * np.array([0.9, 0.3]) - 5)))
    )
    assert len(MotDetections.from_file(path, min_confidence=0.5).for_frame(0)) == 1
    assert len(calibrated.for_frame(7)) == 0  # a frame without rows


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1,-1,10,20,30,60,0.9\n1,-1,oops,20,30,60,0.9\n", r":2: expected numbers"),
        ("1,-1,10,20,30,60,0.9\n\n1,-1,10,20\n", r":3: expected at least 7 columns"),
        ("1,-1,10,20,nan,60,0.9\n", r":1: non-finite"),
    ],
)
def test_malformed_lines_name_the_line(tmp_path, text, message):
    path = tmp_path / "det.txt"
    path.write_text(text)
    with pytest.raises(MotFormatError, match=message):
        MotDetections.from_file(path)


def test_missing_file_and_empty_file(tmp_path):
    with pytest.raises(MotFormatError, match="not found"):
        read_mot_rows(tmp_path / "none.txt")
    empty = tmp_path / "empty.txt"
    empty.write_text("\n")
    assert MotDetections.from_file(empty).num_frames == 0


def test_whitespace_separated_rows(tmp_path):
    path = tmp_path / "det.txt"
    path.write_text("2 -1 10 20 30 60 0.8 -1 -1 -1\n")
    assert MotDetections.from_file(path).for_frame(1).boxes.tolist() == [[9, 19, 30, 60]]


def test_file_pixel_1_1_is_image_pixel_0_0(tmp_path):
    # MOTChallenge counts frames and pixels from 1; detections come out 0-based in both
    path = tmp_path / "det.txt"
    path.write_text("1,-1,1,1,30,60,0.9,-1,-1,-1\n3,-1,101.5,51.25,20,40,0.8,-1,-1,-1\n")
    dets = MotDetections.from_file(path)
    assert dets.for_frame(0).boxes.tolist() == [[0, 0, 30, 60]]
    assert dets.for_frame(2).boxes.tolist() == [[100.5, 50.25, 20, 40]]
    assert read_mot_rows(path)[:, 2:6].tolist() == [[1, 1, 30, 60], [101.5, 51.25, 20, 40]]


def test_ground_truth_boxes_are_0_based(tmp_path):
    (tmp_path / "img1").mkdir()
    (tmp_path / "gt").mkdir()
    for number in (1, 2):
        cv2.imwrite(str(tmp_path / "img1" / f"{number:06d}.jpg"), np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "gt" / "gt.txt").write_text(
        "1,1,1,1,10,20,1,-1,-1,-1\n2,1,5,7,10,20,1,-1,-1,-1\n2,2,9,9,4,4,0,-1,-1,-1\n"
    )
    sequence = MotSequence.open(tmp_path)
    assert sequence.gt[0].tolist() == [[0, 0, 10, 20]]
    assert sequence.gt[1].tolist() == [[4, 6, 10, 20]]  # the flag-0 row is left out


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[Sequence\nname=x\n", "seqinfo.ini: File contains no section headers"),
        ("[Other]\nname=x\n", "seqinfo.ini: no \\[Sequence\\] section"),
    ],
)
def test_a_malformed_seqinfo_is_a_format_error(tmp_path, text, message):
    # before: a configparser error escaped, or a file without [Sequence] was quietly ignored
    (tmp_path / "seqinfo.ini").write_text(text)
    with pytest.raises(MotFormatError, match=message):
        MotSequence.open(tmp_path)


def test_seqinfo_names_the_image_folder(tmp_path):
    (tmp_path / "frames").mkdir()
    (tmp_path / "gt").mkdir()
    cv2.imwrite(str(tmp_path / "frames" / "000001.png"), np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "gt" / "gt.txt").write_text("1,1,1,1,4,4,1,-1,-1,-1\n")
    (tmp_path / "seqinfo.ini").write_text("[Sequence]\nname=S\nimDir=frames\nimExt=.png\n")
    sequence = MotSequence.open(tmp_path)
    assert (sequence.name, [p.name for p in sequence.frames]) == ("S", ["000001.png"])


def test_pets_ground_truth_is_the_file_moved_by_one_pixel(pets):
    file_rows = read_mot_rows(pets.path / "gt" / "gt.txt")
    np.testing.assert_array_equal(pets.gt[0], file_rows[file_rows[:, 0] == 1, 2:6] - [1, 1, 0, 0])


def test_submitted_detections_per_frame():
    sub = SubmittedDetections()
    sub.submit(0, [[10, 10, 20, 40]], [0.7])
    two = [[30, 10, 20, 40], [80, 10, 20, 40]]
    # raw scores alone: refused (they were clipped to certain and impossible)
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\] \(got -1 to 2\)"):
        sub.submit(2, two, [2.0, -1.0])
    sub.submit(2, two, [2.0, -1.0], [0.9, 0.2])
    assert sub.detect(None).boxes.tolist() == [[10, 10, 20, 40]]  # frame 0
    assert len(sub.detect(None)) == 0  # frame 1: nothing handed in
    third = sub.detect(None)  # frame 2
    np.testing.assert_array_equal(third.probabilities, [0.9, 0.2])
    with pytest.raises(ValueError, match="already past"):
        sub.submit(1, [[0, 0, 1, 1]], [1.0])
    assert sub.dense_scores(None, Box(0, 0, 1, 1)) is None


def test_submitted_detections_are_bounded():
    sub = SubmittedDetections(max_pending=2)
    sub.submit(5, np.zeros((0, 4)), [])
    sub.submit(6, np.zeros((0, 4)), [])
    with pytest.raises(ValueError, match="waiting"):
        sub.submit(7, np.zeros((0, 4)), [])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"boxes": [[0, 0, 1]], "scores": [1.0]}, r"boxes must have shape \(N, 4\), got \(1, 3\)"),
        ({"boxes": [[0, 0, 1, 1]], "scores": [1.0, 2.0]}, r"scores must have shape \(1,\)"),
        ({"boxes": [[0, 0, 0, 1]], "scores": [1.0]}, "positive width"),
        ({"boxes": [[0, np.inf, 1, 1]], "scores": [1.0]}, "finite"),
        ({"boxes": [[0, 0, 1, 1]], "scores": [1.0], "probabilities": [1.5]}, r"\[0, 1\]"),
        (
            {"boxes": [[0, 0, 1, 1]], "scores": [1.0], "parts": np.zeros((1, 2, 4))},
            r"parts must have shape \(1, 0, 4\)",
        ),
    ],
)
def test_detections_from_arrays_validates(kwargs, message):
    with pytest.raises(ValueError, match=message):
        detections_from_arrays(**kwargs)


def test_detections_from_arrays_with_parts():
    d = detections_from_arrays(
        [[0, 0, 10, 20]], [0.8], parts=np.ones((1, 1, 4)), part_names=("head",)
    )
    assert d.part_names == ("head",) and d.probabilities.tolist() == [0.8]
