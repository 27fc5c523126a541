"""`vtrack analyze --detections det.txt`: people tracked from public detections (the same boxes
for every tracker, as MOTChallenge compares them) instead of our detector's."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.service.conftest import PETS_VIDEO
from tests.service.test_analyze_cli import vtrack
from tracking.detection.external import MotDetections

pytestmark = pytest.mark.slow


def _iou(a, b) -> float:
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    w = max(0.0, min(ax + aw, bx + bw) - max(ax, bx))
    h = max(0.0, min(ay + ah, by + bh) - max(ay, by))
    return w * h / (aw * ah + bw * bh - w * h)


def test_people_are_tracked_from_the_public_detections(shared_data, tmp_path):
    sequence = shared_data / "mot" / "PETS09-S2L1"
    out = tmp_path / "out"
    detections = sequence / "det" / "det.txt"
    args = ["--detections", detections, "--end", "2", "--format", "json"]
    result = vtrack("analyze", sequence, "--out-dir", out, *args)
    assert result.returncode == 0, result.stderr
    assert f"with the detections of {detections}" in result.stderr
    document = json.loads((out / "trajectories.json").read_text())
    assert document["frames_processed"] == 14  # 2 s at 7 frames per second
    table = MotDetections.from_file(detections)
    measured = [
        (point["frame_index"], point["box"])
        for track in document["tracks"]
        for point in track["frames"]
        if not point["occluded"]
    ]
    assert len({index for index, _ in measured}) >= 10 and len(document["tracks"]) >= 3
    # each box the tracker reports sits on a detection of its frame
    overlaps = [
        max(_iou(tuple(box.values()), d) for d in table.for_frame(index).boxes)
        for index, box in measured
    ]
    assert np.median(overlaps) > 0.5


def test_detections_of_larger_frames_are_scaled_and_refused_unscaled(shared_data, tmp_path):
    video = shared_data / PETS_VIDEO  # 480x360; the detections were made on 768x576
    detections = shared_data / "mot" / "PETS09-S2L1" / "det" / "det.txt"
    base = ["analyze", video, "--detections", detections, "--end", "1", "--format", "json"]
    refused = vtrack(*base, "--out-dir", tmp_path / "a")
    assert refused.returncode == 2 and not (tmp_path / "a").exists()
    assert "boxes reach x=760, y=564, far beyond the 480x360 frames" in refused.stderr
    scaled = vtrack(*base, "--detections-scale", "0.625", "--out-dir", tmp_path / "b")
    assert scaled.returncode == 0, scaled.stderr
    boxes = [
        point["box"]
        for track in json.loads((tmp_path / "b" / "trajectories.json").read_text())["tracks"]
        for point in track["frames"]
    ]
    assert boxes and max(b["x"] + b["w"] for b in boxes) < 480 * 1.05


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--upscale", "2"], "--detections replaces the detector: --upscale would do nothing"),
        (["--detection-interval", "0.5"], ": --detection-interval would do nothing"),
        (
            ["--options", '{"detector": {"upscale": 1.5}}'],
            "--detections replaces the detector: --options: detector would do nothing",
        ),
        (["--box", "1,1,20,40"], "--detections gives people to track, not with --box"),
        (["--detections-scale", "0"], "--detections-scale: must be greater than 0"),
    ],
)
def test_options_that_would_do_nothing_beside_detections_are_refused(
    shared_data, tmp_path, args, message
):
    sequence = shared_data / "mot" / "PETS09-S2L1"
    out = tmp_path / "out"
    detections = ["--detections", sequence / "det" / "det.txt"]
    result = vtrack("analyze", sequence, "--out-dir", out, *detections, *args)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert message in result.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "--detections: mot file not found"),
        (b"1,-1,10,10,5\n", "expected at least 7"),
        # frames from 1, whole: were taken as frame 3 (3.5) or never matched (0), silently
        (b"3.5,-1,10,10,5,5,0.9\n", "det.txt:1: the frame number 3.5 is not a whole number"),
        (b"1,-1,1,1,5,5,1\n0,-1,10,10,5,5,0.9\n", "det.txt:2: the frame number 0 is not"),
    ],
)
def test_a_detections_file_that_is_not_one_is_named(shared_data, tmp_path, content, message):
    path = tmp_path / "det.txt"
    if content is not None:
        path.write_bytes(content)
    sequence = shared_data / "mot" / "PETS09-S2L1"
    result = vtrack("analyze", sequence, "--out-dir", tmp_path / "out", "--detections", path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert message in result.stderr.lower()


def test_detections_scale_alone_is_refused(shared_data, tmp_path):
    video = shared_data / PETS_VIDEO
    result = vtrack("analyze", video, "--out-dir", tmp_path / "out", "--detections-scale", "2")
    assert result.returncode == 2
    assert "--detections-scale scales the boxes of --detections, which is not given" in (
        result.stderr
    )


@pytest.mark.parametrize(
    ("shift", "message"),
    [
        (1000, "no row of {path} is for the 7 frames tracked (its rows are for frames 1001-1795"),
        (None, "{path} has no rows: nobody was tracked"),
    ],
)
def test_detections_that_miss_every_tracked_frame_are_warned_of(
    shared_data, tmp_path, shift, message
):
    # another video's detections (or none) track nobody: the run says so rather than quietly
    # writing empty trajectories
    sequence = shared_data / "mot" / "PETS09-S2L1"
    path = tmp_path / "det.txt"
    lines = (sequence / "det" / "det.txt").read_text().splitlines() if shift else []
    path.write_text(
        "".join(f"{int(line.split(',')[0]) + shift},{line.split(',', 1)[1]}\n" for line in lines)
    )
    args = ["--out-dir", tmp_path / "out", "--detections", path, "--end", "1"]
    result = vtrack("analyze", sequence, *args, "--format", "json")
    assert result.returncode == 0, result.stderr
    assert f"vtrack: warning: --detections: {message.format(path=path)}" in result.stderr
    document = json.loads((tmp_path / "out" / "trajectories.json").read_text())
    assert document["tracks"] == []


def test_rows_without_a_size_and_confidences_beyond_probabilities_are_warned_of(
    shared_data, tmp_path
):
    # a detector's raw scores (here -2..2) were clipped to 0-1 without a word, and rows of
    # negative width left out silently
    sequence = shared_data / "mot" / "PETS09-S2L1"
    rows = [line.split(",") for line in (sequence / "det" / "det.txt").read_text().splitlines()]
    rows = [[*r[:6], f"{4 * float(r[6]) - 2:g}", *r[7:]] for r in rows if int(r[0]) <= 7]
    rows[0][4] = "-" + rows[0][4]
    path = tmp_path / "det.txt"
    path.write_text("".join(",".join(r) + "\n" for r in rows))
    args = ["--out-dir", tmp_path / "out", "--detections", path, "--end", "1", "--format", "json"]
    result = vtrack("analyze", sequence, *args)
    assert result.returncode == 0, result.stderr
    scores = sorted(float(r[6]) for r in rows[1:])
    assert (
        f"vtrack: warning: --detections: {path} has rows without a width or height (1); they "
        "were left out" in result.stderr
    )
    assert (
        f"--detections: the confidences of {path} run from {scores[0]:g} to {scores[-1]:g}; "
        "taken as probabilities they are clipped to 0-1" in result.stderr
    )
