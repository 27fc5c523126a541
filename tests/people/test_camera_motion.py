"""The camera's motion between frames (:mod:`tracking.people.camera_motion`) and the people
tracker that follows it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tracking.detection import Detections
from tracking.detection.nms import box_iou
from tracking.people import MultiPersonTracker, PeopleTrackerConfig
from tracking.people.camera_motion import CameraMotion, warp_boxes, warp_roots
from tracking.people.motion import CX, CY, LOG_H, VX, VY


def _scene(height=360, width=480, seed=0):
    """A textured picture (a street's clutter) larger than the view, so that a view shifted
    within it shows real content everywhere."""
    rng = np.random.default_rng(seed)
    noise = rng.integers(0, 256, (height + 200, width + 200, 3), dtype=np.uint8)
    return cv2.GaussianBlur(noise, (0, 0), 2.0)


def _view(scene, offset, height=360, width=480):
    x, y = 100 + int(offset[0]), 100 + int(offset[1])
    return np.ascontiguousarray(scene[y : y + height, x : x + width])


def test_a_still_camera_has_no_motion():
    camera, frame = CameraMotion(), _view(_scene(), (0, 0))
    assert camera.estimate(frame) is None  # nothing to compare with yet
    assert camera.estimate(frame.copy()) is None


@pytest.mark.parametrize("shift", [(2, 0), (31, -12), (-45, 20)])
def test_a_shift_of_the_view_is_measured_to_a_fraction_of_a_pixel(shift):
    scene, camera = _scene(), CameraMotion()
    assert camera.estimate(_view(scene, (0, 0))) is None  # nothing to compare with yet
    # the camera moves by -shift: the picture's content moves by +shift
    motion = camera.estimate(_view(scene, (-shift[0], -shift[1])))
    assert motion is not None
    np.testing.assert_allclose(motion[:, :2], np.eye(2), atol=0.01)
    np.testing.assert_allclose(motion[:, 2], shift, atol=0.3)


def test_a_rotation_and_zoom_of_the_camera_are_measured():
    frame = _view(_scene(), (0, 0))
    truth = cv2.getRotationMatrix2D((240, 180), 3.0, 1.05)  # degrees, scale
    camera = CameraMotion()
    camera.estimate(frame)
    moved = cv2.warpAffine(frame, truth, frame.shape[1::-1], borderMode=cv2.BORDER_REFLECT)
    motion = camera.estimate(moved)
    assert motion is not None
    np.testing.assert_allclose(motion[:, :2], truth[:, :2], atol=0.005)
    np.testing.assert_allclose(motion[:, 2], truth[:, 2], atol=1.0)


def test_a_blank_picture_gives_no_estimate():
    camera = CameraMotion()
    blank = np.full((240, 320, 3), 90, np.uint8)
    assert camera.estimate(blank) is None and camera.estimate(blank) is None


def test_a_person_walking_over_a_bare_background_is_not_taken_for_the_camera():
    texture = _scene()[:60, :24]
    frames = []
    for x in (100, 112):  # the person walks 12 pixels; the camera stays
        frame = np.full((240, 320, 3), 90, np.uint8)
        frame[80:140, x : x + 24] = texture
        frames.append(frame)
    person = np.array([[100.0, 80.0, 24.0, 60.0]])
    fooled, camera = CameraMotion(), CameraMotion()
    fooled.estimate(frames[0])
    camera.estimate(frames[0], person)
    motion = fooled.estimate(frames[1])  # the person's corners are the only ones
    assert motion is not None and motion[0, 2] == pytest.approx(12, abs=0.5)
    assert camera.estimate(frames[1], person) is None  # none left: no estimate, no false move


def test_particles_and_boxes_move_alike():
    motion = cv2.getRotationMatrix2D((100, 50), 10.0, 1.2)
    box = np.array([[40.0, 20.0, 20.0, 50.0]])
    roots = np.array([[50.0, 45.0, np.log(50.0), 3.0, 1.0]])
    warp_roots(roots, motion)
    moved = warp_boxes(box, motion)[0]
    np.testing.assert_allclose(roots[0, [CX, CY]], moved[:2] + moved[2:] / 2)
    assert np.exp(roots[0, LOG_H]) == pytest.approx(moved[3])
    np.testing.assert_allclose(roots[0, [VX, VY]], motion[:, :2] @ [3.0, 1.0])


def test_a_person_keeps_the_id_through_a_jerk_beyond_walking_reach():
    """The camera knocked by 0.8 of the person's height in one frame: beyond where a person can
    walk (a new person for the tracker that ignores the camera), the same one for the tracker
    that follows the camera."""
    scene = _scene()
    ids = {}
    for follows in (False, True):
        tracker = MultiPersonTracker(PeopleTrackerConfig(camera_motion=follows))
        for index in range(24):
            camera = (0, 0) if index < 15 else (-48, 0)  # the view moves left: content right
            frame = _view(scene, camera).copy()
            box = np.array([60.0 + 2 * index - camera[0], 120.0, 24.0, 60.0])
            x, y, w, h = box.astype(int)
            frame[y : y + h, x : x + w] = (200, 40, 40)  # the person, in a red coat
            detections = Detections(box[None], np.ones(1), np.full(1, 0.9), np.zeros((1, 0, 4)))
            tracks = tracker.update(frame, index / 10, detections)
            if index >= 18:
                assert box_iou(tracks.boxes, box[None]).max() > 0.7
        ids[follows] = tracks.track_ids.tolist()
    assert ids == {False: [2], True: [1]}
