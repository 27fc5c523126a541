"""The multi-person tracker on scenes the tests draw, on a real sequence, and on bad input."""

import dataclasses

import numpy as np
import pytest
from scipy import ndimage

from tracking.detection import Detections
from tracking.detection.base import DenseScores
from tracking.detection.calibration import LogisticCalibration
from tracking.detection.nms import box_iou
from tracking.people import EMBEDDED_BODY, MultiPersonTracker, PeopleTrackerConfig
from tracking.types import Box

HEIGHT, WIDTH = 260, 420
PART_COLOURS = np.array(
    [
        [250, 220, 180],  # head
        [200, 30, 30],  # left_shoulder
        [30, 30, 200],  # right_shoulder
        [30, 160, 30],  # left_hip
        [200, 200, 30],  # right_hip
        [160, 30, 160],  # left_knee
        [30, 160, 160],  # right_knee
        [90, 60, 20],  # left_foot
        [240, 130, 20],  # right_foot
    ],
    dtype=np.uint8,
)


def _texture(rng, shape, sigma):
    noise = ndimage.gaussian_filter(rng.standard_normal(shape), (sigma, sigma, 0))
    noise -= noise.min()
    return (255 * noise / noise.max()).astype(np.uint8)


class Figure:
    """A textured body with nine coloured parts drawn where the body model puts them, plus a
    sway that the part filters must follow (the arms' and legs' offsets change over time)."""

    def __init__(self, rng, height, bottom, x0, speed, torso_colour):
        self.height, self.bottom, self.x0, self.speed = height, bottom, x0, speed
        self.body = _texture(rng, (height, int(0.41 * height), 3), 3.0) // 2 + torso_colour // 2

    def centre(self, t):
        return self.x0 + self.speed * t, self.bottom - self.height / 2

    def box(self, t):
        cx, cy = self.centre(t)
        w = 0.41 * self.height
        return np.array([cx - w / 2, cy - self.height / 2, w, self.height])

    def parts(self, t):
        """Part centres (9, 2): the model's mean offsets with a swing of the knees and feet."""
        offsets = EMBEDDED_BODY.mean.copy()
        swing = 0.04 * np.sin(0.5 * t)
        offsets[5:, 0] += np.array([swing, -swing, swing, -swing])
        return np.array(self.centre(t)) + self.height * offsets

    def draw(self, frame, t):
        x, y, w, h = (round(v) for v in self.box(t))
        region = frame[y : y + h, x : x + w]
        rows, cols = (
            min(region.shape[0], self.body.shape[0]),
            min(region.shape[1], self.body.shape[1]),
        )
        region[:rows, :cols] = self.body[:rows, :cols]
        r = max(int(0.05 * self.height), 2)
        for (px, py), colour in zip(self.parts(t), PART_COLOURS, strict=True):
            px, py = round(px), round(py)
            frame[max(py - r, 0) : py + r, max(px - r, 0) : px + r] = colour


def crossing_scene(frames=44, seed=0):
    """Figure A (nearer: its box ends lower) walks right, B walks left; they cross mid-way.

    Returns frames, per-frame detections (B's is withheld while A covers most of it, as a
    detector would miss it), the true boxes and part positions, and which frames B is covered.
    """
    rng = np.random.default_rng(seed)
    background = _texture(rng, (HEIGHT, WIDTH, 3), 4.0) // 3 + 60
    a = Figure(rng, 120, 235, 60.0, 7.0, np.array([40, 40, 160], np.uint8))
    b = Figure(rng, 104, 215, 360.0, -7.0, np.array([160, 120, 40], np.uint8))
    images, detections, covered = [], [], []
    for t in range(frames):
        frame = background.copy()
        b.draw(frame, t)
        a.draw(frame, t)  # A is nearer: drawn over B
        images.append(frame)
        box_a, box_b = a.box(t), b.box(t)
        x1, x2 = max(box_a[0], box_b[0]), min(box_a[0] + box_a[2], box_b[0] + box_b[2])
        y1, y2 = max(box_a[1], box_b[1]), min(box_a[1] + box_a[3], box_b[1] + box_b[3])
        share = max(x2 - x1, 0) * max(y2 - y1, 0) / (box_b[2] * box_b[3])
        covered.append(share > 0.3)
        people = [(box_a, a.parts(t))] + ([] if share > 0.5 else [(box_b, b.parts(t))])
        size = 0.1 * np.array([[a.height, a.height]])
        detections.append(
            Detections(
                boxes=np.array([p[0] for p in people]),
                scores=np.ones(len(people)),
                probabilities=np.full(len(people), 0.95),
                parts=np.array(
                    [np.hstack([p[1] - size / 2, np.repeat(size, 9, 0)]) for p in people]
                ),
                part_names=EMBEDDED_BODY.names,
            )
        )
    return images, detections, (a, b), np.array(covered)


def _nearest_id(tracks, centre):
    tracks = list(tracks)  # TrackEstimates, or a FrameTracks' rows as TrackEstimates
    distances = [np.hypot(*(np.array(t.box.center) - centre)) for t in tracks]
    return tracks[int(np.argmin(distances))].track_id if tracks else None


def test_two_people_crossing_keep_their_ids_and_parts():
    images, detections, (a, b), covered = crossing_scene()
    # report_occluded: B is reported while covered, so the test can see its flag.
    tracker = MultiPersonTracker(PeopleTrackerConfig(confirm_hits=2, report_occluded=True))
    history, part_errors = [], []
    for t, (frame, dets) in enumerate(zip(images, detections, strict=True)):
        tracks = tracker.update(frame, t / 10.0, dets)
        history.append({tr.track_id: tr for tr in tracks})
        if t > 5 and not covered[t]:
            track = history[-1][_nearest_id(tracks, a.centre(t))]
            drawn = a.parts(t)
            part_errors += [
                np.hypot(p.x - drawn[k, 0], p.y - drawn[k, 1]) for k, p in enumerate(track.parts)
            ]
    # The ids of A and B before the crossing (frame 10) are the ids nearest them after it.
    id_a = _nearest_id(list(history[10].values()), a.centre(10))
    id_b = _nearest_id(list(history[10].values()), b.centre(10))
    last = len(images) - 1
    assert id_a != id_b
    assert _nearest_id(list(history[last].values()), a.centre(last)) == id_a
    assert _nearest_id(list(history[last].values()), b.centre(last)) == id_b
    # While A covers B, B is still reported, flagged occluded; A never is.
    flags = [history[t][id_b].occluded for t in np.flatnonzero(covered) if id_b in history[t]]
    assert len(flags) >= 0.8 * covered.sum() and all(flags)
    assert not any(h[id_a].occluded for h in history if id_a in h)
    # A's parts (measured by the detections' part boxes) follow where they are drawn.
    assert np.median(part_errors) < 3.0 and np.percentile(part_errors, 90) < 6.0


def test_covered_parts_are_reported_not_visible():
    images, detections, _, _covered = crossing_scene()
    tracker = MultiPersonTracker(PeopleTrackerConfig(confirm_hits=2, report_occluded=True))
    hidden = []
    for t, (frame, dets) in enumerate(zip(images, detections, strict=True)):
        for track in tracker.update(frame, t / 10.0, dets):
            if track.occluded:
                hidden.append(sum(not p.visible for p in track.parts))
    assert hidden and max(hidden) > 0


def test_parts_say_whether_the_frame_placed_them():
    """A detector with part boxes measures the parts of the people it finds; one without them
    leaves every part to the body model, and the output says so rather than calling a
    template position seen."""
    from tracking.people.config import default_part_appearance

    images, detections, _, _covered = crossing_scene(frames=16)
    stripped = [
        Detections(d.boxes, d.scores, d.probabilities, np.zeros((len(d), 0, 4))) for d in detections
    ]

    def measured_share(config, frames):
        tracker = MultiPersonTracker(config)
        flags = [
            p.measured
            for t, (frame, dets) in enumerate(zip(images, frames, strict=True))
            for track in tracker.update(frame, t / 10.0, dets)
            for p in track.parts
        ]
        assert flags, "people are reported"
        return np.mean(flags)

    config = PeopleTrackerConfig(confirm_hits=2)
    assert measured_share(config, detections) > 0.9
    assert measured_share(config, stripped) == 0.0
    with_trackers = dataclasses.replace(config, part_appearance=default_part_appearance())
    assert measured_share(with_trackers, stripped) > 0.5


# -- bad input -------------------------------------------------------------------------------


def _frame(h=120, w=160):
    return np.full((h, w, 3), 90, np.uint8)


def _detections(boxes):
    boxes = np.asarray(boxes, dtype=float).reshape(-1, 4)
    n = len(boxes)
    return Detections(boxes, np.ones(n), np.full(n, 0.9), np.zeros((n, 0, 4)))


def test_timestamps_going_backwards_are_refused():
    tracker = MultiPersonTracker()
    tracker.update(_frame(), 1.0, _detections([]))
    with pytest.raises(ValueError, match="backwards"):
        tracker.update(_frame(), 0.5, _detections([]))


def test_a_change_of_frame_size_starts_again():
    tracker = MultiPersonTracker(PeopleTrackerConfig(confirm_hits=1))
    assert len(tracker.update(_frame(), 0.0, _detections([[40, 20, 30, 70]]))) == 1
    out = tracker.update(_frame(200, 300), 0.1, _detections([[100, 50, 30, 70]]))
    # the old tracks end (nothing carries over into the new geometry); ids are never reused
    assert [t.track_id for t in out] == [2]


@pytest.mark.parametrize("gap", [10.0, 1e9])
def test_a_long_gap_between_frames_ends_the_tracks_and_tracking_goes_on(gap):
    # a camera clock jumping from relative to Unix time: the prediction over 1e9 s grew the
    # boxes until patch extraction failed deep inside numpy ("Maximum allowed size exceeded")
    tracker = MultiPersonTracker(PeopleTrackerConfig(confirm_hits=1))
    first = tracker.update(_frame(), 0.0, _detections([[40, 20, 30, 70]]))
    tracker.update(_frame(), 0.1, _detections([[41, 20, 30, 70]]))
    out = tracker.update(_frame(), 0.1 + gap, _detections([[120, 40, 30, 70]]))
    assert [t.track_id for t in first] == [1]
    # the old track is over (it could only be re-identified); the new person is tracked
    assert len(out) == 1 and np.isfinite(out.boxes).all()
    assert 110 < out.boxes[0, 0] < 130


@pytest.mark.parametrize(
    "boxes",
    [
        [],  # no detections at all
        [[500, 500, 30, 60]],  # entirely outside the frame
        [[-40, -80, 30, 60]],  # above and left of the frame
        [[150, 100, 40, 80]],  # centre inside, box sticking out
        [[10, 10, 0.5, 0.5]],  # a speck
    ],
)
def test_odd_detections_give_a_sane_result(boxes):
    tracker = MultiPersonTracker(PeopleTrackerConfig(confirm_hits=1))
    for t in range(3):
        out = tracker.update(_frame(), t * 0.1, _detections(boxes))
    assert all(np.isfinite(tr.box.as_array()).all() for tr in out)


def test_without_detections_or_detector_it_says_so():
    with pytest.raises(ValueError, match="no detections"):
        MultiPersonTracker().update(_frame(), 0.0)


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        (np.zeros((0, 0, 3), np.uint8), "empty"),
        (np.zeros((50, 50), np.uint8), "RGB"),
        (np.zeros((50, 50, 4), np.uint8), r"\(H, W, 3\)"),
    ],
)
def test_malformed_frames_are_refused(frame, message):
    with pytest.raises(ValueError, match=message):
        MultiPersonTracker().update(frame, 0.0, _detections([]))


def test_frames_and_detections_of_the_wrong_type_are_refused_at_once():
    # was: cv2.error deep in the colour signatures for uint16, a TypeError only once a track
    # started for float, AttributeError for a list of boxes, and "cannot convert float NaN to
    # integer" for NaN boxes
    frame = _frame()
    for odd in (frame.astype(np.uint16), frame.astype(np.float32)):
        with pytest.raises(TypeError, match="needs a uint8 frame"):
            MultiPersonTracker().update(odd, 0.0, _detections([[40, 20, 30, 70]]))
    with pytest.raises(TypeError, match="detections must be a tracking"):
        MultiPersonTracker().update(frame, 0.0, [[40, 20, 30, 70]])
    with pytest.raises(ValueError, match="boxes must be finite"):
        _detections([[np.nan, 20, 30, 70]])


def test_nan_timestamp_is_refused():
    with pytest.raises(ValueError, match="finite"):
        MultiPersonTracker().update(_frame(), float("nan"), _detections([]))


def test_part_trackers_follow_moving_limbs_without_detected_parts():
    """Detections without part boxes (as the embedded detector gives): the knees and feet
    swing +-0.04 heights about the body model; with per-part RCSK trackers they stay within a
    few pixels of where they are drawn. Over three seeds, since one seed's particle draws move
    a median by a pixel either way; the trackers are about as close as the body model here
    (no closer: their errors reach the root), so that comparison gets a pixel's slack."""
    from tracking.people.config import default_part_appearance

    images, detections, (a, _), covered = crossing_scene()
    stripped = [
        Detections(d.boxes, d.scores, d.probabilities, np.zeros((len(d), 0, 4))) for d in detections
    ]

    def leg_errors(config):
        errors = []
        for seed in range(3):
            errors += seed_errors(dataclasses.replace(config, seed=seed))
        return np.median(errors)

    def seed_errors(config):
        tracker = MultiPersonTracker(config)
        errors = []
        for t, (frame, dets) in enumerate(zip(images, stripped, strict=True)):
            tracks = tracker.update(frame, t / 10.0, dets)
            if t > 5 and not covered[t] and tracks:
                track = min(tracks, key=lambda o: np.hypot(*(np.array(o.box.center) - a.centre(t))))
                drawn = a.parts(t)
                errors += [
                    np.hypot(p.x - drawn[k, 0], p.y - drawn[k, 1])
                    for k, p in enumerate(track.parts)
                    if p.name.endswith(("knee", "foot"))
                ]
        return errors

    model_only = leg_errors(PeopleTrackerConfig(confirm_hits=2))
    tracked = leg_errors(
        PeopleTrackerConfig(confirm_hits=2, part_appearance=default_part_appearance())
    )
    assert tracked < 6.0 and tracked < model_only + 1.0


class _ScoresBeside:
    """A detector that scores densely: its scores peak at 0 ``shift`` px to the right of each
    person of the crossing scene and fall by 1 every twentieth of the person's height squared
    (calibrated: from probability 0.5 down), and it records what the tracker asks it for."""

    part_names = EMBEDDED_BODY.names
    calibration = LogisticCalibration(a=1.0, b=0.0)

    def __init__(self, figures, shift):
        self.figures, self.shift, self.t = figures, shift, 0
        self.asked: list[tuple[Box, tuple[float, float]]] = []

    def detect(self, frame):
        return Detections.empty(self.part_names)

    def detect_region(self, frame, region, heights=None):
        return Detections.empty(self.part_names)

    def dense_scores(self, frame, region, heights=None):
        self.asked.append((region, heights))
        stride = 1.0
        xs = np.arange(region.x, region.x + region.w, stride)
        ys = np.arange(region.y, region.y + region.h, stride)
        score = np.full((ys.size, xs.size), -20.0)
        for figure in self.figures:
            cx, cy = figure.centre(self.t)
            d2 = (xs[None, :] - cx - self.shift) ** 2 + (ys[:, None] - cy) ** 2
            score = np.maximum(score, -d2 / (0.05 * figure.height) ** 2)
        return DenseScores(
            region=region,
            heights=np.array([float(np.mean(heights))]),
            levels=[score],
            origins=np.array([[region.x, region.y]]),
            strides=np.array([stride]),
        )


@pytest.mark.parametrize("dense", [False, True])
def test_dense_scores_pull_the_particles_where_the_detector_scores(dense):
    """With ``dense_likelihood``, every particle is weighed by the detector's calibrated score
    at its position (docs/architecture.md §5): a detector whose scores peak 12 px right of each
    person draws every track a quarter of the way there (3-4 px); without it they stay within a
    pixel and a half of the people."""
    images, detections, (a, b), _ = crossing_scene(frames=12)
    detector = _ScoresBeside((a, b), shift=12.0)
    config = PeopleTrackerConfig(confirm_hits=2, dense_likelihood=dense)
    tracker = MultiPersonTracker(config, detector=detector)
    offsets = []
    for t, (frame, dets) in enumerate(zip(images, detections, strict=True)):
        detector.t = t
        asked = len(detector.asked)
        tracks = tracker.update(frame, t / 10.0, dets)
        if dense and t > 0:
            # one region per person around its predicted box, for people of its height
            assert len(detector.asked) - asked == 2
            for region, (low, high) in detector.asked[asked:]:
                figure = min((a, b), key=lambda f: abs(f.centre(t)[0] - region.center[0]))
                assert low <= figure.height <= high < 2 * low
                assert region.x < figure.centre(t)[0] < region.x + region.w
        if t >= 6:
            offsets += [
                tr.box.center[0] - f.centre(t)[0]
                for f in (a, b)
                for tr in tracks
                if tr.track_id == _nearest_id(tracks, f.centre(t))
            ]
    assert len(offsets) == 12
    if dense:
        assert min(offsets) > 2.5
    else:
        assert max(np.abs(offsets)) < 1.5
        assert detector.asked == []


@pytest.mark.parametrize("jump", [0.3, 0.5])
def test_a_person_whose_detection_jumps_is_followed_at_once_under_its_id(jump):
    """The camera knocked: a person's detection moves ``jump`` heights in one frame, beyond the
    particles' reach but within walking reach of the person (the third association round
    recognises it). On a blank picture the appearance cannot pull the particles over, so before
    the restart at the detection the box stayed beside the person for 1 (0.3) to 4 (0.5)
    frames."""
    tracker = MultiPersonTracker()
    frame = np.full((240, 320, 3), 90, np.uint8)
    for index in range(20):
        box = [40 + 2 * index + (jump * 60 if index >= 15 else 0), 80, 24, 60]
        tracks = tracker.update(frame, index / 10, _detections(box))
        if index >= 14:
            assert tracks.track_ids.tolist() == [1]
            assert box_iou(tracks.boxes, np.array([box]))[0, 0] > 0.8
