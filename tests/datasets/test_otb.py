"""Reading OTB sequences: ground-truth parsing, folder layout, frames, and the real data."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.datasets.otb import (
    OtbSequence,
    SequenceError,
    find_otb_sequences,
    load_otb_sequence,
    parse_ground_truth,
    read_frame,
)
from tracking.types import Box

# The sequences in ../shared/data/otb and their frame counts (shared/data/README.md).
REAL_SEQUENCES = {
    "Basketball_first200": 200,
    "Bird2": 99,
    "Couple": 140,
    "Crossing": 120,
    "Deer": 71,
    "Football1": 74,
    "Freeman1": 326,
    "Skating1": 400,
    "Skiing": 81,
    "Soccer": 392,
}


def write_sequence(folder: Path, gt_text: str, frames: int, suffix: str = ".jpg") -> Path:
    """An OTB folder with ``frames`` small images and the given ground-truth text."""
    (folder / "img").mkdir(parents=True)
    for index in range(1, frames + 1):
        image = np.full((12, 16, 3), index, dtype=np.uint8)
        cv2.imwrite(str(folder / "img" / f"{index:04d}{suffix}"), image)
    (folder / "groundtruth_rect.txt").write_text(gt_text)
    return folder


@pytest.mark.parametrize(
    "text",
    [
        "11,21,30,40\n2,3,4,5\n",  # commas (most OTB sequences)
        "11\t21\t30\t40\n2\t3\t4\t5\n",  # tabs (e.g. Crossing)
        "11 21 30 40\n2 3 4 5\n",  # single spaces
        "11, 21,\t30  40\n2 ,3\t\t4,5",  # a mix, repeated separators, no final newline
        "11,21,30,40\r\n2,3,4,5\r\n\r\n",  # Windows line ends and a trailing blank line
    ],
)
def test_parse_separators(text: str) -> None:
    expected = np.array([[10.0, 20.0, 30.0, 40.0], [1.0, 2.0, 4.0, 5.0]])
    assert np.array_equal(parse_ground_truth(text), expected)


def test_parse_converts_one_based_corner_only() -> None:
    # x and y lose 1 (the first pixel is 1 in OTB, 0 here); width and height are unchanged
    boxes = parse_ground_truth("1,1,10,20\n0.5,7.25,3.5,4\n")
    assert np.array_equal(boxes, [[0.0, 0.0, 10.0, 20.0], [-0.5, 6.25, 3.5, 4.0]])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        # three values on line 2
        ("1,2,3,4\n1,2,3\n", "line 2: expected 4 values"),
        # five values on line 1
        ("1,2,3,4,5\n", "line 1: expected 4 values"),
        # not numbers
        ("1,2,3,4\n5,6,7,8\nx,y,w,h\n", "line 3: expected 4 numbers"),
        # a blank line inside would shift every later frame
        ("1,2,3,4\n\n5,6,7,8\n", "line 2: expected 4 values"),
        # nothing at all
        ("\n\n", "no ground-truth boxes"),
    ],
)
def test_parse_rejects_malformed(text: str, message: str) -> None:
    with pytest.raises(SequenceError, match=message):
        parse_ground_truth(text, source="gt.txt")


def test_load_sequence(tmp_path: Path) -> None:
    folder = write_sequence(tmp_path / "Toy", "3,4,5,6\n4,5,5,6\n5,6,5,6\n", frames=3)
    sequence = load_otb_sequence(folder)
    assert isinstance(sequence, OtbSequence)
    assert sequence.name == "Toy"
    assert len(sequence) == 3
    assert [p.name for p in sequence.frame_paths] == ["0001.jpg", "0002.jpg", "0003.jpg"]
    assert sequence.ground_truth.dtype == np.float64
    assert np.array_equal(sequence.ground_truth[0], [2.0, 3.0, 5.0, 6.0])
    assert sequence.box(2) == Box(4.0, 5.0, 5.0, 6.0)
    assert not sequence.ground_truth.flags.writeable


def test_more_images_than_boxes_uses_the_first(tmp_path: Path) -> None:
    # like a sequence cut to its first frames: only as many frames as ground-truth rows
    folder = write_sequence(tmp_path / "Cut", "1,1,4,4\n2,2,4,4\n", frames=5)
    sequence = load_otb_sequence(folder)
    assert [p.name for p in sequence.frame_paths] == ["0001.jpg", "0002.jpg"]


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        # the folder does not exist
        (lambda root: root / "Nowhere", "does not exist"),
        # no ground-truth file
        (lambda root: (root / "NoGt").mkdir() or root / "NoGt", "has no groundtruth_rect.txt"),
        # ground truth but no images
        (
            lambda root: write_sequence(root / "NoImg", "1,1,4,4\n", frames=0),
            "has no images",
        ),
        # fewer images than ground-truth rows
        (
            lambda root: write_sequence(root / "Short", "1,1,4,4\n" * 4, frames=2),
            "4 ground-truth rows but only 2 images",
        ),
        # a malformed ground-truth line is reported with the file and the line
        (
            lambda root: write_sequence(root / "Bad", "1,1,4,4\n1;1;4;4\n", frames=2),
            r"Bad.groundtruth_rect\.txt, line 2",
        ),
    ],
)
def test_load_sequence_errors(tmp_path: Path, setup, message: str) -> None:
    with pytest.raises(SequenceError, match=message):
        load_otb_sequence(setup(tmp_path))


def test_sequence_error_is_a_value_error() -> None:
    assert issubclass(SequenceError, ValueError)


def test_find_sequences_sorted_and_only_with_ground_truth(tmp_path: Path) -> None:
    write_sequence(tmp_path / "b_seq", "1,1,4,4\n", frames=1)
    write_sequence(tmp_path / "a_seq", "1,1,4,4\n", frames=1, suffix=".png")
    (tmp_path / "not_a_sequence").mkdir()
    (tmp_path / "notes.txt").write_text("ignored")
    assert [s.name for s in find_otb_sequences(tmp_path)] == ["a_seq", "b_seq"]


@pytest.mark.parametrize(
    "make_root",
    [
        lambda root: root / "missing",  # no such folder
        lambda root: root,  # an empty folder holds no sequence
    ],
)
def test_find_sequences_errors(tmp_path: Path, make_root) -> None:
    with pytest.raises(SequenceError):
        find_otb_sequences(make_root(tmp_path))


def test_read_frame_is_rgb(tmp_path: Path) -> None:
    bgr = np.zeros((6, 8, 3), dtype=np.uint8)
    bgr[..., 0] = 255  # pure blue in OpenCV's BGR order
    path = tmp_path / "blue.png"  # lossless, so the values survive exactly
    cv2.imwrite(str(path), bgr)
    frame = read_frame(path)
    assert frame.dtype == np.uint8
    assert frame.shape == (6, 8, 3)
    assert np.all(frame[..., 2] == 255) and np.all(frame[..., :2] == 0)


@pytest.mark.parametrize(
    "make_path",
    [
        lambda root: root / "missing.jpg",  # no such file
        lambda root: (root / "text.jpg").write_text("not an image") and root / "text.jpg",
    ],
)
def test_read_frame_errors(tmp_path: Path, make_path) -> None:
    with pytest.raises(SequenceError, match="cannot read image"):
        read_frame(make_path(tmp_path))


@pytest.mark.slow
def test_real_otb_sequences(shared_data: Path) -> None:
    sequences = find_otb_sequences(shared_data / "otb")
    assert {s.name: len(s) for s in sequences} == REAL_SEQUENCES
    for sequence in sequences:
        assert sequence.ground_truth.shape == (len(sequence.frame_paths), 4)
        assert np.all(sequence.ground_truth[:, 2:] > 0), sequence.name
        frame = read_frame(sequence.frame_paths[0])
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        x, y, w, h = sequence.ground_truth[0]
        assert 0 <= x <= x + w <= frame.shape[1]
        assert 0 <= y <= y + h <= frame.shape[0]


@pytest.mark.slow
def test_real_ground_truth_is_zero_based(shared_data: Path) -> None:
    # Deer's first row in the file is "306,5,95,65" (1-based); Crossing's is tab-separated
    deer = load_otb_sequence(shared_data / "otb" / "Deer")
    assert np.array_equal(deer.ground_truth[0], [305.0, 4.0, 95.0, 65.0])
    crossing = load_otb_sequence(shared_data / "otb" / "Crossing")
    assert np.array_equal(crossing.ground_truth[0], [204.0, 150.0, 17.0, 50.0])
