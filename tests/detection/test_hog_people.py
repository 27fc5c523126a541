"""The embedded default: OpenCV's HOG people detector behind the Detector protocol."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.detection.hog_people import HogPeopleConfig, HogPeopleDetector
from tracking.evaluation.detection import match_frame
from tracking.types import Box


@pytest.fixture(scope="module")
def detector() -> HogPeopleDetector:
    return HogPeopleDetector()


def test_no_parts(detector):
    assert detector.part_names == ()


def test_detects_the_people_of_a_pets_frame(detector, pets):
    # frame 201 (index 200): seven people 55-100 px tall. At 1.5x the window's 96-px person is
    # 64 px, so most are found: 6 of 7 at IoU >= 0.5 here; 4 is the floor, and it shows the
    # boxes are shrunk onto the person (the unshrunk windows match none of the seven).
    frame, gt = pets.read_frame(200), pets.gt[200]
    found = detector.detect(frame)
    assert found.parts.shape == (len(found), 0, 4)
    assert int(match_frame(found.boxes, found.scores, gt).sum()) >= 4
    assert np.all((found.probabilities >= 0) & (found.probabilities <= 1))


@pytest.mark.parametrize("height", [1080, 2160])
def test_detects_the_people_of_a_large_frame(detector, pets, height):
    # The same frame as a 1080p or 4K camera would show it: searched at 1080 px high (1.0x and
    # 0.5x), where its people are 100-190 px tall, well above the window's 96-px person.
    frame, scale = pets.read_frame(200), height / 576
    large = cv2.resize(frame, (round(768 * scale), height), interpolation=cv2.INTER_LINEAR)
    found = detector.detect(large)
    assert int(match_frame(found.boxes, found.scores, pets.gt[200] * scale).sum()) >= 5


def test_detects_the_people_of_a_portrait_frame(detector, pets):
    # The same frame in a 768x1366 corridor-format picture (a camera turned on its side): it is
    # enlarged by its shorter side as the 1366x768 frame would be (1.41x), so its 55-100 px
    # people are found as in the frame itself; by its height (0.79x) they would be under the
    # window's 96-px person.
    frame, gt = pets.read_frame(200), pets.gt[200]
    top = (1366 - 576) // 2
    portrait = np.zeros((1366, 768, 3), np.uint8)
    portrait[top : top + 576] = frame
    found = detector.detect(portrait)
    assert int(match_frame(found.boxes, found.scores, gt + np.array([0, top, 0, 0])).sum()) >= 4


def test_dense_scores_agree_with_the_detection(detector, pets, pets_frame):
    gt = pets.gt[0][1]
    x, y, w, h = gt
    region = Box(x + w / 2 - 0.25 * h, y + h / 2 - 0.25 * h, 0.5 * h, 0.5 * h)
    dense = detector.dense_scores(pets_frame, region, (0.8 * h, 1.25 * h))
    assert dense is not None and len(dense.levels) >= 3
    assert np.all(np.diff(dense.heights) > 0)
    assert dense.part_offsets == [] and dense.part_names == ()
    roi = detector.detect_region(pets_frame, region, (0.8 * h, 1.25 * h))
    assert len(roi) >= 1
    # four numbers, as trackers take boxes (before: TypeError, a Box only)
    numbers = detector.detect_region(pets_frame, region.as_array().tolist(), (0.8 * h, 1.25 * h))
    assert np.array_equal(numbers.boxes, roi.boxes)
    # the SVM scores in the grid are the ones detect thresholds: the best is positive and
    # the person is found near the best position
    best = max(float(g.max()) for g in dense.levels)
    assert best > 0
    assert match_frame(roi.boxes, roi.scores, gt[None]).any()


def test_a_region_scans_only_the_levels_of_its_heights(pets, pets_frame):
    # Every level of the crop's pyramid costs a tracker that searches regions between full
    # searches more than the whole frame's search; only those of the heights asked for are
    # scanned.
    scales = []

    class Recording(HogPeopleDetector):
        def _level_windows(self, image, scale):
            scales.append(scale)
            return super()._level_windows(image, scale)

    recording = Recording()
    x, y, w, h = pets.gt[0][1]
    heights = (0.8 * h, 1.25 * h)
    found = recording.detect_region(pets_frame, Box(x - h / 2, y - h / 2, w + h, 2 * h), heights)
    u = recording.config.upscale_for(pets_frame.shape)
    person = recording.config.box_scale[1] * 128 * np.array(scales) / u
    assert len(scales) >= 3
    assert np.all((person >= heights[0]) & (person <= heights[1]))
    assert match_frame(found.boxes, found.scores, pets.gt[0][1][None]).any()
    assert np.all((found.boxes[:, 3] >= heights[0]) & (found.boxes[:, 3] <= heights[1]))


def test_outside_regions_and_small_frames(detector, pets_frame):
    assert len(detector.detect_region(pets_frame, Box(2000, 0, 10, 10))) == 0
    assert detector.dense_scores(pets_frame, Box(2000, 0, 10, 10)) is None
    assert len(detector.detect(np.zeros((20, 30, 3), np.uint8))) == 0
    with pytest.raises(ValueError):
        detector.detect(np.zeros((0, 5, 3), np.uint8))


@pytest.mark.parametrize("dtype", [np.uint16, np.float32, np.float64, np.bool_])
def test_a_frame_that_is_not_uint8_is_refused(detector, pets_frame, dtype):
    # was: clipped to 0..255 without a word (a 16-bit frame white, a 0..1 float frame black:
    # no people found, no error)
    with pytest.raises(TypeError, match="needs a uint8 frame"):
        detector.detect(pets_frame.astype(dtype))


@pytest.mark.parametrize(
    "options",
    [
        {"upscale": -1.0},
        {"scale_step": 1.0},
        {"win_stride": 0},
        {"win_stride": 2.5},  # OpenCV would fail deep in detectMultiScale
        {"box_scale": (0.5, 1.5)},
        {"workers": 0},
        {"nms_criterion": "union"},
    ],
)
def test_bad_config(options):
    with pytest.raises(ValueError):
        HogPeopleConfig(**options)


def test_iou_suppression_keeps_people_walking_close(pets):
    # PETS09-S2L1 frame 349 (index 348): six people, two pairs among them. Three of them have
    # only windows that lie mostly inside a larger, higher-scoring window of a neighbour:
    # intersection over the smaller window drops them, intersection over union keeps them
    # (with more false windows: 12 boxes against 6).
    frame, gt = pets.read_frame(348), pets.gt[348]
    matched = {}
    for criterion in ("smaller", "iou"):
        found = HogPeopleDetector(HogPeopleConfig(nms_criterion=criterion)).detect(frame)
        matched[criterion] = int(match_frame(found.boxes, found.scores, gt).sum())
    assert len(gt) == 6
    assert matched["iou"] == 6
    assert matched["smaller"] <= 4


def test_default_upscale_follows_the_frame_height():
    config = HogPeopleConfig()
    # 480x360 video: people 40-60 px tall need 2.0; 640x480 and 768x576 keep the fitted 1.5;
    # frames above 720 px are searched at 1080 px high, so a 4K frame is shrunk, not enlarged.
    expected = {240: 2.0, 360: 2.0, 400: 1.8, 480: 1.5, 576: 1.5, 720: 1.5, 800: 1.35,
                1080: 1.0, 2160: 0.5}  # fmt: skip
    for height, factor in expected.items():
        width = round(height * 16 / 9)
        assert config.upscale_for((height, width, 3)) == pytest.approx(factor)
        # a camera turned for a corridor: the shorter side counts, as for the frame upright
        assert config.upscale_for((width, height, 3)) == pytest.approx(factor)
    assert config.upscale_for((360, 480)) == 2.0  # greyscale shapes too
    assert HogPeopleConfig(upscale=1.0).upscale_for((2160, 3840, 3)) == 1.0
    with pytest.raises(ValueError, match="auto_heights"):
        HogPeopleConfig(auto_heights=(1080.0, 720.0))
    with pytest.raises(ValueError, match="max_upscale"):
        HogPeopleConfig(max_upscale=0.0)


def test_the_same_frame_gives_the_same_detections_on_any_number_of_threads(
    pets_frame, opencv_threads
):
    # OpenCV's detectMultiScale pairs windows with scores wrongly when its level threads
    # finish together (two locks, OpenCV 4.x): 64 near-equal levels of every window on 16
    # threads made 92 of 100 calls differ from the single-threaded result. The detector scans
    # the levels itself, so every call agrees. No suppression: every window and its score show.
    crop = np.ascontiguousarray(pets_frame[:160, :96])
    config = HogPeopleConfig(upscale=1.0, scale_step=1.002, hit_threshold=-9.0, nms_overlap=1.0)
    opencv_threads(1)
    reference = HogPeopleDetector(config).detect(crop)
    assert len(reference) > 500
    opencv_threads(16)
    detector = HogPeopleDetector(config)
    for _ in range(20):
        found = detector.detect(crop)
        np.testing.assert_array_equal(found.boxes, reference.boxes)
        np.testing.assert_array_equal(found.scores, reference.scores)


@pytest.mark.parametrize("workers", [1, 3])
def test_windows_are_opencvs(pets_frame, opencv_threads, workers):
    # The pyramid, resizing, window positions and clipping of detectMultiScale, window for
    # window in its single-threaded order.
    opencv_threads(1)
    image = np.ascontiguousarray(pets_frame)
    hog = cv2.HOGDescriptor()
    hog.setSVMDetector(cv2.HOGDescriptor_getDefaultPeopleDetector())
    for step, threshold in [(1.05, -1.0), (1.1, 0.0)]:
        rects, weights = hog.detectMultiScale(
            image, hitThreshold=threshold, winStride=(8, 8), scale=step, groupThreshold=0
        )
        config = HogPeopleConfig(scale_step=step, hit_threshold=threshold, workers=workers)
        windows, scores = HogPeopleDetector(config)._windows(image)
        assert len(scores) > 5
        np.testing.assert_array_equal(windows, np.asarray(rects, float).reshape(-1, 4))
        np.testing.assert_array_equal(scores, np.ravel(weights))
