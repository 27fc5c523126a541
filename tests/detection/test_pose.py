"""The OpenPose decoder (:mod:`tracking.detection.pose`) on heatmaps and part affinity fields
built by hand, and Open Model Zoo's human-pose-estimation-0001 on real PETS09-S2L1 frames."""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from pathlib import Path

import cv2
import numpy as np
import pytest

import tracking.detection.pose as pose_module
from tracking.datasets.mot import MotSequence
from tracking.detection.cnn import CnnModelError
from tracking.detection.pose import (
    KEYPOINT_NAMES,
    LIMBS,
    PoseConfig,
    PoseEstimator,
    Poses,
    decode_openpose,
    find_peaks,
    group_people,
)

POSE_MODEL = "human-pose-estimation-0001/FP16-INT8/human-pose-estimation-0001.xml"
K = len(KEYPOINT_NAMES)
# A standing person in map cells, relative to the neck's x (the order of KEYPOINT_NAMES): the
# right side at smaller x, as a person facing the camera.
TEMPLATE = np.array(
    [
        [0, 2], [0, 5], [-3, 5], [-4, 9], [-4, 13], [3, 5], [4, 9], [4, 13], [-2, 14],
        [-2, 19], [-2, 24], [2, 14], [2, 19], [2, 24], [-1, 1], [1, 1], [-2, 2], [2, 2],
    ],
    dtype=float,
)  # fmt: skip
SHAPE = (40, 60)  # map height, width


def _person(x: float, y: float) -> np.ndarray:
    return TEMPLATE + np.array([x, y])


def _maps(
    people: list[np.ndarray], reversed_limbs: frozenset[tuple[int, int]] = frozenset()
) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth-like maps (Cao et al. sec. 2.2-2.3): a Gaussian (sigma 1 cell) per keypoint,
    and per limb the unit vector from its first keypoint to its second on the cells within 1 of
    the segment, averaged where people overlap. A NaN keypoint is absent (no peak, no limb);
    ``(person, limb)`` in ``reversed_limbs`` points the wrong way."""
    height, width = SHAPE
    ys, xs = np.mgrid[0:height, 0:width].astype(float)
    heat = np.zeros((K + 1, height, width), dtype=np.float32)
    pafs = np.zeros((2 * len(LIMBS), height, width), dtype=np.float32)
    counts = np.zeros((len(LIMBS), height, width))
    for p, points in enumerate(people):
        for k, (x, y) in enumerate(points):
            if not np.isnan(x):
                heat[k] = np.maximum(heat[k], np.exp(-((xs - x) ** 2 + (ys - y) ** 2) / 2))
        for limb, (a, b, channel) in enumerate(LIMBS):
            start, end = points[a], points[b]
            if np.isnan(start).any() or np.isnan(end).any():
                continue
            direction = (end - start) / np.linalg.norm(end - start)
            along = (xs - start[0]) * direction[0] + (ys - start[1]) * direction[1]
            across = np.abs((xs - start[0]) * direction[1] - (ys - start[1]) * direction[0])
            on = (along >= 0) & (along <= np.linalg.norm(end - start)) & (across <= 1)
            sign = -1.0 if (p, limb) in reversed_limbs else 1.0
            pafs[channel][on] += sign * direction[0]
            pafs[channel + 1][on] += sign * direction[1]
            counts[limb][on] += 1
    for limb, (_, _, channel) in enumerate(LIMBS):
        pafs[channel : channel + 2] /= np.maximum(counts[limb], 1)
    heat[K] = 1 - heat[:K].max(axis=0)
    return heat, pafs


def _peaks(people: list[np.ndarray]) -> list[np.ndarray]:
    """The keypoints as the candidates find_peaks gives, score 0.9."""
    return [
        np.array([[*p[k], 0.9] for p in people if not np.isnan(p[k]).any()]).reshape(-1, 3)
        for k in range(K)
    ]


def _by_neck(poses: Poses) -> Poses:
    order = np.argsort(poses.keypoints[:, 1, 0])
    return Poses(poses.keypoints[order], poses.scores[order], poses.person_scores[order])


# -- decoder on synthetic maps -----------------------------------------------------------------


def test_two_people_with_consistent_fields_are_two_whole_skeletons():
    people = [_person(12, 5), _person(40, 8)]
    _, pafs = _maps(people)
    poses = _by_neck(group_people(_peaks(people), pafs))
    assert len(poses) == 2
    np.testing.assert_allclose(poses.keypoints, np.stack(people))
    np.testing.assert_allclose(poses.scores, 0.9)
    assert np.all(poses.person_scores > 18 * 0.9)  # keypoints plus limb scores


def test_limbs_scored_in_several_passes_group_as_in_one(monkeypatch):
    """A crowd's candidate limbs are scored in passes of bounded size: the skeletons are the
    same whatever the bound."""
    people = [_person(12, 5), _person(40, 8), _person(26, 11)]
    _, pafs = _maps(people)
    peaks = _peaks(people)
    once = group_people(peaks, pafs)
    monkeypatch.setattr(pose_module, "_PAIRS_PER_PASS", 1)  # one limb type per pass
    passes = group_people(peaks, pafs)
    np.testing.assert_array_equal(passes.keypoints, once.keypoints)
    np.testing.assert_array_equal(passes.person_scores, once.person_scores)
    assert len(once) == 3


def test_a_missing_keypoint_is_nan_and_scores_zero():
    second = _person(40, 8)
    second[KEYPOINT_NAMES.index("left_wrist")] = np.nan
    people = [_person(12, 5), second]
    _, pafs = _maps(people)
    poses = _by_neck(group_people(_peaks(people), pafs))
    assert len(poses) == 2
    wrist = KEYPOINT_NAMES.index("left_wrist")
    assert np.isnan(poses.keypoints[1, wrist]).all() and poses.scores[1, wrist] == 0
    assert poses.found().sum(axis=1).tolist() == [18, 17]
    np.testing.assert_allclose(np.delete(poses.keypoints[1], wrist, 0), np.delete(second, wrist, 0))


def test_a_limb_whose_field_points_the_wrong_way_is_not_joined():
    people = [_person(12, 5), _person(40, 8)]
    elbow_wrist = LIMBS.index((3, 4, 16))  # right elbow -> right wrist, at the chain's end
    _, pafs = _maps(people, reversed_limbs=frozenset({(0, elbow_wrist)}))
    poses = _by_neck(group_people(_peaks(people), pafs))
    assert len(poses) == 2
    wrist = KEYPOINT_NAMES.index("right_wrist")
    assert np.isnan(poses.keypoints[0, wrist]).all()  # the first person's wrist stays alone
    np.testing.assert_allclose(poses.keypoints[1], people[1])  # the other's limb still joins


def test_a_skeleton_of_too_few_keypoints_is_dropped():
    lone = np.full((K, 2), np.nan)
    lone[[0, 1]] = [[30, 10], [30, 14]]  # nose and neck only: one limb
    _, pafs = _maps([lone])
    assert len(group_people(_peaks([lone]), pafs)) == 0
    assert len(group_people(_peaks([lone]), pafs, min_keypoints=2)) == 1


def test_peaks_are_local_maxima_above_the_threshold_one_per_plateau():
    heat = np.zeros((2, 20, 30), dtype=np.float32)
    heat[0, 5, 7] = 0.8
    heat[0, 5, 8] = 0.5  # beside the first: not a maximum
    heat[0, 15, 25] = 0.3
    heat[0, 0, 0] = 0.05  # under the threshold
    heat[1, 10:12, 10:12] = 0.6  # a 2x2 plateau: one peak
    heat[1, 19, 29] = 0.4  # at the corner
    peaks = find_peaks(heat, threshold=0.1, radius=3)
    np.testing.assert_allclose(peaks[0], [[7, 5, 0.8], [25, 15, 0.3]], rtol=1e-6)
    np.testing.assert_allclose(peaks[1], [[10, 10, 0.6], [29, 19, 0.4]], rtol=1e-6)


def test_equal_peaks_apart_all_stay_and_each_map_keeps_its_best_few():
    heat = np.zeros((3, 20, 30), dtype=np.float32)  # map 0: nobody
    heat[1, 4, 4] = heat[1, 4, 9] = 0.5  # equal, 5 apart: both windows' maxima
    heat[1, 5, 11] = 0.5  # equal to the one 2 columns and a row before it: a plateau, goes
    heat[2, 2, 2], heat[2, 10, 10], heat[2, 18, 28] = 0.3, 0.9, 0.6
    peaks = find_peaks(heat, threshold=0.1, radius=3, max_peaks=2)
    assert [len(p) for p in peaks] == [0, 2, 2]
    np.testing.assert_allclose(peaks[1], [[4, 4, 0.5], [9, 4, 0.5]])  # raster order
    np.testing.assert_allclose(peaks[2], [[10, 10, 0.9], [28, 18, 0.6]], rtol=1e-6)


def test_decode_maps_keypoints_back_to_frame_pixels():
    people = [_person(12, 5), _person(40, 8)]
    heat, pafs = _maps(people)
    # stride 8, frame shrunk by 2 for the input: cell f is input pixel 8 f + 3.5, frame
    # pixel (8 f + 4) / 0.5 - 0.5
    poses = _by_neck(decode_openpose(heat[None], pafs[None], 0.5, stride=8))
    assert len(poses) == 2
    expected = (8 * np.stack(people) + 4) / 0.5 - 0.5
    # the 4 times enlarged heatmaps put a cell centre between two of their pixels: 1/8 cell
    np.testing.assert_allclose(poses.keypoints, expected, atol=8 / 8 / 0.5 + 1e-6)


def test_boxes_bound_the_found_keypoints():
    keypoints = np.full((2, K, 2), np.nan)
    keypoints[0, :3] = [[10, 20], [14, 30], [8, 25]]
    poses = Poses(keypoints, np.zeros((2, K)), np.zeros(2))
    boxes = poses.boxes()
    np.testing.assert_allclose(boxes[0], [8, 20, 6, 10])
    assert np.isnan(boxes[1]).all()
    assert Poses.empty().boxes().shape == (0, 4) and len(Poses.empty()) == 0


def test_input_keeps_the_frame_aspect_and_a_shorter_side_of_576_to_1080():
    config = PoseConfig()
    assert config.input_for((576, 768, 3)) == (768, 576)
    assert config.input_for((360, 640, 3)) == (1024, 576)  # enlarged 1.6
    assert config.input_for((2160, 3840, 3)) == (1920, 1088)  # shrunk by 2, rounded to 32
    with pytest.raises(ValueError, match="stride"):
        PoseConfig(stride=12)


# -- the real model -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def estimator(shared_data: Path) -> PoseEstimator:
    return PoseEstimator.from_file(shared_data / "models" / POSE_MODEL, PoseConfig(threads=1))


def _people_with_a_skeleton(poses: Poses, people: np.ndarray) -> np.ndarray:
    """Which ground-truth boxes ``x, y, w, h`` hold the neck or a hip of some skeleton, with
    most of its keypoints inside."""
    if len(poses) == 0:
        return np.zeros(len(people), dtype=bool)
    x, y = poses.keypoints[None, ..., 0], poses.keypoints[None, ..., 1]
    bx, by, bw, bh = (people[:, i, None, None] for i in range(4))
    with np.errstate(invalid="ignore"):
        inside = (x >= bx) & (x <= bx + bw) & (y >= by) & (y <= by + bh)  # (people, poses, 18)
    torso = inside[..., [1, 8, 11]].any(axis=-1)
    most = inside.sum(axis=-1) >= 0.5 * poses.found().sum(axis=-1)
    return (torso & most).any(axis=1)


def test_the_model_puts_a_skeleton_on_most_pets_people(estimator: PoseEstimator, pets):
    found = total = 0
    for index in (100, 200, 700):  # 21 people, some side by side
        poses = estimator.estimate(pets.read_frame(index))
        people = pets.gt[index]
        found += int(_people_with_a_skeleton(poses, people).sum())
        total += len(people)
        # keypoints land in the frame, skeletons have at least 3 of them
        assert np.all(poses.found().sum(axis=1) >= 3)
        held = poses.keypoints[poses.found()]
        assert np.all((held >= -1) & (held <= [768, 576]))
    assert total == 21
    assert found >= 0.85 * total, (found, total)


def test_a_greyscale_frame_works(estimator: PoseEstimator, pets: MotSequence):
    grey = cv2.cvtColor(pets.read_frame(0), cv2.COLOR_RGB2GRAY)
    people = pets.gt[0]
    poses = estimator.estimate(grey)
    assert _people_with_a_skeleton(poses, people).sum() >= len(people) - 1


def test_a_file_that_is_not_a_model_is_refused(tmp_path: Path):
    xml = tmp_path / "pose.xml"
    xml.write_text("<net><layers>not a graph</net>")
    xml.with_suffix(".bin").write_bytes(b"\x00" * 64)
    with pytest.raises(CnnModelError):
        PoseEstimator.from_file(xml)


def test_a_model_without_heatmaps_and_fields_is_refused(shared_data: Path):
    detector = shared_data / "models" / "person-detection-0200/FP16/person-detection-0200.xml"
    with pytest.raises(CnnModelError, match="not an OpenPose network"):
        PoseEstimator.from_file(detector, PoseConfig(threads=1))


# -- crops around people ------------------------------------------------------------------------


def test_crops_are_used_while_they_feed_the_network_fewer_pixels_than_the_frame(
    estimator: PoseEstimator,
):
    network_input = 768 * 576  # a 576-line frame's, at its size
    assert estimator.config.crop_size == (96, 192)
    most = (network_input - 1) // (96 * 192)
    assert estimator.crops_cheaper((576, 768, 3), most)
    assert not estimator.crops_cheaper((576, 768, 3), most + 1)
    no_crops = PoseEstimator(estimator.network, PoseConfig(crop_size=None))
    assert not no_crops.crops_cheaper((576, 768, 3), 1)


@pytest.mark.parametrize(
    "options",
    [{"crop_size": (100, 192)}, {"crop_size": (96,)}, {"crop_margin": -0.1}, {"max_batch": 0}],
)
def test_crop_options_that_cannot_work_are_refused(options):
    with pytest.raises(ValueError):
        PoseConfig(**options)


def test_crops_put_each_person_s_skeleton_where_the_whole_frame_does(
    estimator: PoseEstimator, pets: MotSequence
):
    """The crops' keypoints come back in frame pixels: on 21 PETS people (one crop each, in
    batches of 4 and 1), the skeleton that fills a crop's box has its neck within a tenth of
    the person's height of the whole frame's skeleton's neck; both find nearly everyone."""
    from tracking.people.keypoints import skeletons_in_crops

    in_crops = in_frame = close = 0
    for index in (100, 200, 700):
        frame, people = pets.read_frame(index), pets.gt[index]
        crops = estimator.estimate_crops(frame, people)
        assert len(crops) == len(people)
        keypoints, _, owner = skeletons_in_crops(
            [(c.keypoints, c.scores) for c in crops], KEYPOINT_NAMES, people, 0.6
        )
        whole = estimator.estimate(frame)
        in_crops += int((owner >= 0).sum())
        in_frame += int(_people_with_a_skeleton(whole, people).sum())
        for person, neck in zip(people, keypoints[:, 1], strict=True):
            distance = np.linalg.norm(whole.keypoints[:, 1] - neck, axis=1)
            if np.isfinite(neck).all() and np.nanmin(distance, initial=np.inf) < 0.1 * person[3]:
                close += 1
    assert in_crops >= 19 and in_frame >= 19, (in_crops, in_frame)  # of 21
    assert close >= 0.8 * in_frame, (close, in_frame)


def test_boxes_without_a_crop_get_no_skeleton(estimator: PoseEstimator, pets: MotSequence):
    frame = pets.read_frame(100)
    person = pets.gt[100][0]
    boxes = np.array([[np.nan, 0, 10, 10], [5, 5, 10, 0], person, [-40, -80, 30, 90]])
    crops = estimator.estimate_crops(frame, boxes)
    assert [len(c) for c in crops[:2]] == [0, 0]
    assert len(crops[2]) >= 1  # the real person
    assert len(crops) == 4  # a box off the frame's corner is a black crop, not an error
    grey = estimator.estimate_crops(cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY), person[None])
    assert len(grey[0]) >= 1
    assert estimator.estimate_crops(frame, np.zeros((0, 4))) == []


def test_after_prepare_crops_no_number_of_people_compiles_anything(
    estimator: PoseEstimator, pets: MotSequence
):
    """A live stream compiles every batch of crops up front (PoseEstimator.prepare_crops):
    the crops of 1 to 9 people then find every shape compiled."""
    network = dataclasses.replace(estimator.network, _compiled=OrderedDict())
    fresh = PoseEstimator(network, estimator.config)
    fresh.prepare_crops()
    prepared = list(network._compiled)
    assert len(prepared) == fresh.config.max_batch
    frame, people = pets.read_frame(100), pets.gt[100]
    for count in range(1, 10):
        fresh.estimate_crops(frame, people[:count])
    assert sorted(network._compiled) == sorted(prepared)
    PoseEstimator(network, dataclasses.replace(estimator.config, crop_size=None)).prepare_crops()
    assert sorted(network._compiled) == sorted(prepared)  # crops off: nothing to prepare
