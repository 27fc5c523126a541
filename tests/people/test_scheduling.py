"""Detector scheduling: full searches now and then, cheap searches around the tracks between."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.datasets.mot import MotSequence
from tracking.detection import MotDetections
from tracking.detection.base import Detections
from tracking.detection.hog_people import HogPeopleDetector
from tracking.people import MultiPersonTracker, PeopleTrackerConfig
from tracking.people.scheduling import DetectionScheduler, search_regions
from tracking.types import Box

SHAPE = (480, 640, 3)


def test_a_lone_person_is_searched_around_their_box_at_their_height():
    [(region, heights)] = search_regions(np.array([[300, 100, 40, 100]]), SHAPE, 0.5, (0.8, 1.25))
    assert region == Box(250, 50, 140, 200)
    assert heights == pytest.approx((80, 125))


def test_a_group_is_one_search_and_people_apart_are_searched_apart():
    group = [[100, 100, 40, 100], [130, 105, 40, 100], [160, 95, 40, 100]]
    apart = [[500, 300, 40, 100]]
    regions = search_regions(np.array(group + apart), SHAPE, 0.5, (0.8, 1.25))
    assert len(regions) == 2
    (together, heights), (alone, _) = sorted(regions, key=lambda r: r[0].x)
    # the box around the three regions, for the heights of all three
    assert together == Box(50, 45, 200, 210)
    assert heights == pytest.approx((80, 125))
    assert alone == Box(450, 250, 140, 200)


def test_a_near_and_a_far_person_overlapping_are_searched_apart():
    # One search of the box around both would scan the near person's large region at the far
    # person's small scale: far more pixels than the two searches.
    near, far = [200, 100, 120, 300], [300, 150, 12, 30]
    regions = search_regions(np.array([near, far]), SHAPE, 0.5, (0.8, 1.25))
    assert sorted(h for _, (_, h) in regions) == pytest.approx([37.5, 375])


def test_regions_are_clipped_to_the_frame_and_those_outside_dropped():
    boxes = np.array([[-30, -20, 40, 100], [700, 100, 40, 100], [620, 400, 40, 100]])
    regions = search_regions(boxes, SHAPE, 0.5, (0.8, 1.25))
    assert [r for r, _ in regions] == [Box(0, 0, 60, 130), Box(570, 350, 70, 130)]
    assert search_regions(np.zeros((0, 4)), SHAPE, 0.5, (0.8, 1.25)) == []


@pytest.mark.parametrize("heights", [(0.0, 1.0), (1.3, 1.2)])
def test_bad_region_heights_are_refused(heights):
    with pytest.raises(ValueError, match="region_heights"):
        PeopleTrackerConfig(region_heights=heights)


class _CountingDetector(HogPeopleDetector):
    """The embedded detector, adding up the pixels of the pyramid levels it scans."""

    def __init__(self) -> None:
        super().__init__()
        self.pixels = 0.0
        self.full_searches = 0

    def _level_windows(self, image, scale):
        self.pixels += image.shape[0] * image.shape[1] / scale**2
        return super()._level_windows(image, scale)

    def detect(self, frame):
        self.full_searches += 1
        return super().detect(frame)


class _Searches:
    """A detector that finds nobody and notes which frames it searched in full."""

    part_names = ()

    def __init__(self) -> None:
        self.full: list[int] = []
        self.frame = 0

    def detect(self, frame):
        self.full.append(self.frame)
        return Detections.empty(())

    def detect_region(self, frame, region, heights=None):
        return Detections.empty(())


@pytest.mark.parametrize(
    ("fps", "interval", "jitter", "expected"),
    [
        (25.0, 0.2, 0.0, list(range(0, 60, 5))),  # 0.6 - 0.4 < 0.2 in floating point
        (25.0, 0.2, 0.003, list(range(0, 60, 5))),  # a camera clock's jitter
        (7.0, 0.2, 0.0, list(range(0, 60, 2))),  # the first frame 0.2 s on
        (30.0, 0.5, 0.002, list(range(0, 60, 15))),
    ],
)
def test_full_searches_fall_on_the_frame_the_interval_reaches(fps, interval, jitter, expected):
    detector = _Searches()
    scheduler = DetectionScheduler(detector, PeopleTrackerConfig(full_detection_interval=interval))
    frame = np.zeros(SHAPE, dtype=np.uint8)
    predicted = np.array([[100.0, 100.0, 40.0, 100.0]])
    jitters = np.random.default_rng(0).uniform(-jitter, jitter, 60)
    for index in range(60):
        detector.frame = index
        scheduler.detect(frame, index / fps + jitters[index], predicted)
    assert detector.full == expected


@pytest.mark.slow
def test_between_full_searches_the_tracker_searches_less_and_keeps_the_people(shared_data):
    """TUD-Stadtmitte (25 fps, a group of people), a full search every 0.4 s.

    On the frames between full searches the regions around the tracks scan at most half the
    pixels of a full search (a sixth here; before regions were restricted to the tracks'
    heights and merged, they scanned more than the whole frame), and the people stay tracked:
    as many boxes as on the full-search frames, to within a fifth.
    """
    sequence = MotSequence.open(shared_data / "mot" / "TUD-Stadtmitte")
    detector = _CountingDetector()
    tracker = MultiPersonTracker(
        PeopleTrackerConfig(full_detection_interval=0.4), detector=detector
    )
    frames = {True: [], False: []}  # full search or not: (pixels scanned, boxes reported)
    for index in range(60):
        searches, detector.pixels = detector.full_searches, 0.0
        tracks = tracker.update(sequence.read_frame(index), index / 25.0)
        frames[detector.full_searches > searches].append((detector.pixels, len(tracks)))
    full, between = np.array(frames[True]), np.array(frames[False])
    assert len(full) == 6  # frames 0, 10, 20...
    assert between[:, 0].mean() <= 0.5 * full[:, 0].mean()
    # once the tracks are confirmed (from frame 20)
    assert full[2:, 1].mean() >= 3
    assert between[18:, 1].mean() >= 0.8 * full[2:, 1].mean()


@pytest.mark.slow
def test_detections_from_a_file_as_the_detector_follow_the_frames(shared_data):
    # Before, region searches between full ones did not move the file's frame index, so each
    # full search read an older frame's boxes (HOTA 57 fell to 5 on PETS09-S2L1).
    sequence = MotSequence.open(shared_data / "mot" / "PETS09-S2L1")
    config = PeopleTrackerConfig(full_detection_interval=0.5)
    as_detector = MultiPersonTracker(
        config, detector=MotDetections.from_file(sequence.detections_file)
    )
    handed_in = MultiPersonTracker(config)
    public = MotDetections.from_file(sequence.detections_file)
    for index in range(30):
        frame, t = sequence.read_frame(index), index / 7.0
        ours = as_detector.update(frame, t)
        theirs = handed_in.update(frame, t, public.for_frame(index))
        assert [(k.track_id, k.box) for k in ours] == [(k.track_id, k.box) for k in theirs]
    assert theirs  # people were tracked


@pytest.mark.slow
def test_a_detector_that_batches_gets_the_regions_of_a_frame_in_one_call(shared_data):
    """The CNN searches a frame's regions in one inference (``detect_regions``): the scheduler
    hands it every region at once instead of one ``detect_region`` call per region."""
    from tracking.detection.cnn import CnnConfig, CnnDetector
    from tracking.detection.cnn.runtime import load_network

    class Counting(CnnDetector):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            self.batches: list[int] = []

        def detect_regions(self, frame, regions):
            self.batches.append(len(regions))
            return super().detect_regions(frame, regions)

        def detect_region(self, frame, region, heights=None):
            raise AssertionError("the scheduler called detect_region one region at a time")

    model = shared_data / "models/person-detection-0202/FP16/person-detection-0202.xml"
    sequence = MotSequence.open(shared_data / "mot" / "PETS09-S2L1")
    detector = Counting(load_network(model, 1), CnnConfig(threads=1))
    scheduler = DetectionScheduler(detector, PeopleTrackerConfig(full_detection_interval=10.0))
    frame = sequence.read_frame(100)
    full = scheduler.detect(frame, 0.0, np.zeros((0, 4)))
    assert detector.batches == [] and len(full) >= 5  # the first search is the whole frame
    found = scheduler.detect(sequence.read_frame(101), 0.14, full.boxes)
    assert len(detector.batches) == 1 and detector.batches[0] >= 2
    # the regions keep the people the full search found (IoU 0.5)
    from tracking.detection.nms import box_iou

    assert (box_iou(full.boxes, found.boxes).max(axis=1) >= 0.5).sum() >= len(full) - 1
