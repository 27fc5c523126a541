"""MOTChallenge files: sequence info, rows, the 1-based pixel convention, result files; and the
OpenCV build the project runs on."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.evaluation.mot import (
    MotFileError,
    check_unique_ids,
    find_mot_sequences,
    format_mot_rows,
    frame_rows,
    ground_truth_rows,
    image_to_mot_boxes,
    limit_frames,
    mot_to_image_boxes,
    read_mot_rows,
    read_sequence_info,
    track_rows,
    write_mot_file,
)
from tracking.tracks import FrameTracks

# The MOT sequences in ../shared/data/mot (shared/data/README.md): frames, rate, size, gt rows.
REAL_SEQUENCES = {
    "PETS09-S2L1": (795, 7.0, 768, 576, 4650),
    "TUD-Stadtmitte": (179, 25.0, 640, 480, 1156),
}

SEQINFO = """[Sequence]
name={name}
imDir=img1
frameRate={rate}
seqLength={length}
imWidth=16
imHeight=12
imExt=.jpg
"""


def write_sequence(folder: Path, frames: int = 3, length: int | None = None, rate="7") -> Path:
    """A MOTChallenge folder with ``frames`` small images and a seqinfo.ini."""
    (folder / "img1").mkdir(parents=True)
    for index in range(1, frames + 1):
        cv2.imwrite(
            str(folder / "img1" / f"{index:06d}.jpg"), np.full((12, 16, 3), index, np.uint8)
        )
    text = SEQINFO.format(name=folder.name, rate=rate, length=length or frames)
    (folder / "seqinfo.ini").write_text(text)
    return folder


def test_the_project_runs_on_headless_opencv_4_with_the_hog_people_detector():
    # opencv-python (OpenCV 5, pulled by `trackers` and `trackeval`) must never land in the
    # project environment: its cv2 would shadow this one and it has no HOG people detector.
    assert cv2.__version__.startswith("4."), cv2.__version__
    assert hasattr(cv2, "HOGDescriptor")
    assert len(cv2.HOGDescriptor.getDefaultPeopleDetector()) > 0


# --------------------------------------------------------------------------------- boxes


def test_file_boxes_move_by_one_pixel_to_image_boxes_and_back():
    file_boxes = np.array([[1.0, 1.0, 10.0, 20.0], [243.0, 218.0, 45.0, 90.0]])
    image = mot_to_image_boxes(file_boxes)
    # the first pixel of a MOTChallenge file (1, 1) is pixel (0, 0) of the image; sizes stay
    np.testing.assert_array_equal(image, [[0.0, 0.0, 10.0, 20.0], [242.0, 217.0, 45.0, 90.0]])
    np.testing.assert_array_equal(image_to_mot_boxes(image), file_boxes)
    assert file_boxes[0, 0] == 1.0  # inputs are not modified


def test_track_rows_write_1_based_frames_and_boxes():
    rows = track_rows(0, [7, 2], [[0.0, 0.0, 5.0, 6.0], [10.5, 20.25, 3.0, 4.0]], [0.9, 0.5])
    np.testing.assert_array_equal(
        rows,
        [
            [1, 7, 1.0, 1.0, 5.0, 6.0, 0.9, -1, -1, -1],
            [1, 2, 11.5, 21.25, 3.0, 4.0, 0.5, -1, -1, -1],
        ],
    )


@pytest.mark.parametrize(
    ("ids", "boxes", "scores", "message"),
    [
        ([1, 2], [[0, 0, 1, 1]], None, "boxes must have shape"),  # one box for two ids
        ([-1], [[0, 0, 1, 1]], None, "non-negative"),  # an unconfirmed (-1) id
        ([1.5], [[0, 0, 1, 1]], None, "integers"),  # not an id
        ([1], [[0, np.nan, 1, 1]], None, "finite"),  # a lost box
        ([1], [[0, 0, 1, 1]], [0.1, 0.2], "scores must have shape"),  # scores do not match
    ],
)
def test_track_rows_reject_malformed_input(ids, boxes, scores, message):
    with pytest.raises(ValueError, match=message):
        track_rows(3, ids, boxes, scores)


def test_track_rows_of_an_empty_frame():
    assert track_rows(4, [], np.zeros((0, 4))).shape == (0, 10)


def test_a_frames_tracks_become_rows_with_their_score():
    tracks = FrameTracks(
        9,
        0.9,
        track_ids=[3, 9],
        boxes=[[4.0, 0.0, 2.0, 8.0], [0.0, 1.0, 3.0, 3.0]],
        scores=[0.75, 0.25],
        occluded=[False, True],
        interpolated=[False, False],
        part_names=("head",),
        part_xy=[[[5.0, 2.0]], [[1.0, 2.0]]],
        part_boxes=np.full((2, 1, 4), np.nan),
        part_visible=[[True], [True]],
        part_measured=[[False], [False]],
    )
    rows = frame_rows(tracks)
    np.testing.assert_array_equal(
        rows[:, :7], [[10, 3, 5, 1, 2, 8, 0.75], [10, 9, 1, 2, 3, 3, 0.25]]
    )
    assert frame_rows(FrameTracks.empty(0, 0.0, ("head",))).shape == (0, 10)


# --------------------------------------------------------------------------------- files


def test_rows_survive_a_round_trip_through_a_file(tmp_path):
    rows = np.vstack(
        [
            track_rows(1, [2, 1], [[10.0, 20.0, 30.0, 40.0], [0.5, 0.25, 1.0, 2.0]], [0.5, 1.0]),
            track_rows(0, [1], [[3.0, 4.0, 5.0, 6.0]], [0.87006]),
        ]
    )
    path = write_mot_file(tmp_path / "out" / "SEQ.txt", rows)
    back = read_mot_rows(path, min_columns=6)
    # written sorted by frame, then id
    np.testing.assert_allclose(back, rows[[2, 1, 0]])
    assert path.read_text().splitlines()[0] == "1,1,4.00,5.00,5.00,6.00,0.87006,-1,-1,-1"


def test_an_empty_result_file_is_written_and_read(tmp_path):
    path = write_mot_file(tmp_path / "empty.txt", np.zeros((0, 7)))
    assert path.read_text() == ""
    assert read_mot_rows(path, min_columns=6).shape == (0, 6)


def test_format_pads_short_rows_with_minus_one():
    assert (
        format_mot_rows(np.array([[2, 5, 1, 2, 3, 4, 1]])) == "2,5,1.00,2.00,3.00,4.00,1,-1,-1,-1\n"
    )


def test_a_repeated_id_in_one_frame_is_refused(tmp_path):
    rows = np.array([[1, 4, 0, 0, 1, 1, 1], [2, 4, 0, 0, 1, 1, 1], [2, 4, 5, 5, 1, 1, 1]])
    with pytest.raises(ValueError, match="track id 4 appears more than once in frame 2"):
        check_unique_ids(rows)
    with pytest.raises(ValueError, match="more than once"):
        write_mot_file(tmp_path / "bad.txt", rows)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1,2,3,4,5\n", "expected at least 6 columns"),  # a short row
        ("1,2,3,x,5,6\n", "expected numbers"),  # not a number
        ("1,2,3,4,5,nan\n", "non-finite value"),  # a NaN box
    ],
)
def test_malformed_files_name_their_line(tmp_path, text, message):
    path = tmp_path / "gt.txt"
    path.write_text("1,1,1,1,1,1\n" + text)
    with pytest.raises(MotFileError, match=rf"gt\.txt:2: {message}"):
        read_mot_rows(path, min_columns=6)


def test_reading_accepts_spaces_and_blank_lines(tmp_path):
    path = tmp_path / "det.txt"
    path.write_text("1 -1 5 6 7 8 0.9 -1 -1 -1\n\n2,-1,1,2,3,4,0.5,-1,-1,-1\n")
    np.testing.assert_array_equal(
        read_mot_rows(path)[:, :7], [[1, -1, 5, 6, 7, 8, 0.9], [2, -1, 1, 2, 3, 4, 0.5]]
    )


def test_limit_frames_keeps_the_first_frames():
    rows = np.array([[1, 1, 0, 0, 1, 1], [3, 1, 0, 0, 1, 1], [2, 2, 0, 0, 1, 1]], dtype=float)
    np.testing.assert_array_equal(limit_frames(rows, 2)[:, 0], [1, 2])


# --------------------------------------------------------------------------------- sequences


def test_sequence_info_from_seqinfo_ini(tmp_path):
    info = read_sequence_info(write_sequence(tmp_path / "SEQ-01", frames=4, length=3, rate="25"))
    assert (info.name, info.frame_rate, len(info), info.width, info.height) == (
        "SEQ-01",
        25.0,
        3,
        16,
        12,
    )
    assert [p.name for p in info.frame_paths] == ["000001.jpg", "000002.jpg", "000003.jpg"]
    assert info.timestamp(5) == pytest.approx(0.2)
    assert info.gt_path == tmp_path / "SEQ-01" / "gt" / "gt.txt"
    assert info.det_path == tmp_path / "SEQ-01" / "det" / "det.txt"


@pytest.mark.parametrize(
    ("frames", "length", "rate", "message"),
    [
        (2, 3, "7", "seqLength 3 but 2 images"),  # frames missing
        # no usable frame rate: the file and the key are named, with the value as written
        (2, 2, "0", r"seqinfo\.ini: frameRate '0' is not a positive number of frames per second"),
        (2, 2, "nan", "frameRate 'nan' is not a positive number"),
        # not a number: a sentence, not Python's "could not convert string to float"
        (2, 2, "abc", r"seqinfo\.ini: frameRate 'abc' is not a number of frames per second$"),
        (2, 2, "", "frameRate '' is not a number"),  # the key with no value
    ],
)
def test_bad_sequence_folders_are_refused(tmp_path, frames, length, rate, message):
    folder = write_sequence(tmp_path / "SEQ", frames=frames, length=length, rate=rate)
    with pytest.raises(MotFileError, match=message):
        read_sequence_info(folder)


def test_a_seqinfo_without_frame_rate_says_so(tmp_path):
    folder = write_sequence(tmp_path / "SEQ")
    ini = folder / "seqinfo.ini"
    ini.write_text(ini.read_text().replace("frameRate=7\n", ""))
    with pytest.raises(MotFileError) as caught:
        read_sequence_info(folder)
    assert str(caught.value) == f"{ini} has no frameRate"  # not "..., got nan"


@pytest.mark.parametrize("key", ["seqLength", "imWidth", "imHeight"])
def test_a_seqinfo_size_that_is_not_a_whole_number_is_named(tmp_path, key):
    folder = write_sequence(tmp_path / "SEQ")
    ini = folder / "seqinfo.ini"
    text = "\n".join(
        f"{key}=3.5" if line.startswith(f"{key}=") else line for line in ini.read_text().split("\n")
    )
    ini.write_text(text)
    with pytest.raises(MotFileError, match=rf"seqinfo\.ini: {key} '3\.5' is not a whole number"):
        read_sequence_info(folder)


def test_a_folder_without_seqinfo_is_refused(tmp_path):
    with pytest.raises(MotFileError, match=r"has no seqinfo\.ini"):
        read_sequence_info(tmp_path)


def test_a_missing_sequence_folder_is_named_as_missing(tmp_path):
    with pytest.raises(MotFileError) as caught:
        read_sequence_info(tmp_path / "NoSuch")
    assert str(caught.value) == f"no such sequence folder: {tmp_path / 'NoSuch'}"


def test_find_sequences_in_a_root_or_the_sequence_itself(tmp_path):
    b = write_sequence(tmp_path / "B")
    a = write_sequence(tmp_path / "A")
    (tmp_path / "not-a-sequence").mkdir()
    assert find_mot_sequences(tmp_path) == [a, b]
    assert find_mot_sequences(b) == [b]
    with pytest.raises(MotFileError, match="no MOTChallenge sequence"):
        find_mot_sequences(tmp_path / "not-a-sequence")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REAL_SEQUENCES))
def test_the_shared_sequences(shared_data, name):
    frames, rate, width, height, gt_rows = REAL_SEQUENCES[name]
    info = read_sequence_info(shared_data / "mot" / name)
    assert (info.name, len(info), info.frame_rate, info.width, info.height) == (
        name,
        frames,
        rate,
        width,
        height,
    )
    gt = read_mot_rows(info.gt_path)
    det = read_mot_rows(info.det_path)
    assert gt.shape == (gt_rows, 10)
    # MOT15-style ground truth: every row flagged "consider" (7th column 1), no classes (-1),
    # which is why the benchmark runs TrackEval in its MOT15 mode
    assert np.all(gt[:, 6] == 1) and np.all(gt[:, 7] == -1)
    assert gt[:, 0].min() == 1 and gt[:, 0].max() <= frames
    assert np.all((det[:, 6] >= 0.5) & (det[:, 6] <= 1.0))
    assert np.all(det[:, 1] == -1)


def test_ground_truth_rows_are_0_based_scaled_and_cut_to_the_frames(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_text("1,1,11,21,40,100,1,1,1\n2,1,13,21,40,100,1,1,1\n3,2,101,1,8,16,1,1,1\n")
    rows = ground_truth_rows(path, scale=0.5, frames=2)
    np.testing.assert_array_equal(rows, [[1, 1, 5, 10, 20, 50], [2, 1, 6, 10, 20, 50]])
    assert len(ground_truth_rows(path)) == 3
