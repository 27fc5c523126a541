"""The camera's own motion between consecutive frames, to move the people's particles with it.

A hand-held, vehicle-mounted or knocked camera moves the whole picture: every person jumps by the
same few tens of pixels, which a constant-velocity model does not expect. BoT-SORT's global motion
compensation (Aharon, Orfaig, Bobrovsky, "BoT-SORT: Robust associations multi-pedestrian
tracking", 2022, section 3.2) estimates that motion as a 2-D similarity by sparse optical flow
with RANSAC and applies it to the tracks' Kalman states before prediction; :class:`CameraMotion`
does the same with OpenCV (Shi-Tomasi corners, pyramidal Lucas-Kanade, a RANSAC similarity) and
:func:`warp_roots` applies it to the particles. People are a minority of the picture's corners in
a surveillance view, so RANSAC takes them for outliers; a static camera gets the identity.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from tracking.people.motion import CX, CY, LOG_H, VX, VY

__all__ = ["CameraMotion", "warp_boxes", "warp_roots"]

_MAX_SIDE = 320  # pixels: the picture is shrunk to this before the flow (BoT-SORT: by 2)
_CORNERS = 200
_MIN_INLIERS = 20  # fewer agreeing corners: no estimate (a blank or wholly changed picture)
_MIN_MOTION = 1.0  # pixels: a smaller move of every corner of the frame is the flow's noise


class CameraMotion:
    """Estimates, frame after frame, the similarity that maps the previous frame's pixels to
    the current one's (``2 x 3``, :meth:`estimate`)."""

    def __init__(self) -> None:
        self._previous: np.ndarray | None = None  # the previous frame, grey and shrunk

    def estimate(self, frame: np.ndarray, people: np.ndarray | None = None) -> np.ndarray | None:
        """The motion from the previous frame to ``frame`` (RGB uint8), or None for the first
        frame, a frame of another size, too few corners that agree (then the people are
        predicted by their motion alone) or a motion that moves no corner of the frame by a
        pixel (a static camera). ``people``: boxes ``x, y, w, h`` of the previous
        frame whose corners are not the background's (people move by themselves; on a bare
        background they would be the only corners, and their walk would pass for the
        camera's)."""
        scale = min(1.0, _MAX_SIDE / max(frame.shape[:2]))
        grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
        if scale < 1.0:
            size = (round(frame.shape[1] * scale), round(frame.shape[0] * scale))
            grey = cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
        previous, self._previous = self._previous, grey
        if previous is None or previous.shape != grey.shape:
            return None
        mask = None
        if people is not None and len(people):
            mask = np.full(previous.shape, 255, np.uint8)
            boxes = np.asarray(people, dtype=np.float64).reshape(-1, 4) * scale
            low = np.floor(boxes[:, :2]).astype(int).clip(0)
            high = np.ceil(boxes[:, :2] + boxes[:, 2:]).astype(int).clip(0)
            for (x0, y0), (x1, y1) in zip(low, high, strict=True):  # a few boxes, not pixels
                mask[y0:y1, x0:x1] = 0
        corners = cv2.goodFeaturesToTrack(
            previous, _CORNERS, qualityLevel=0.01, minDistance=5, blockSize=3, mask=mask
        )
        if corners is None or len(corners) < _MIN_INLIERS:
            return None
        moved, found, _ = cv2.calcOpticalFlowPyrLK(previous, grey, corners, corners.copy())
        found = found.ravel() == 1
        if np.count_nonzero(found) < _MIN_INLIERS:
            return None
        similarity, inliers = cv2.estimateAffinePartial2D(
            corners[found], moved[found], method=cv2.RANSAC, ransacReprojThreshold=1.5
        )
        if similarity is None or np.count_nonzero(inliers) < _MIN_INLIERS:
            return None
        similarity[:, 2] /= scale  # the shift in the frame's pixels (rotation, scale unchanged)
        # A static camera's estimates wander by 0.05-0.5 pixels (PETS09-S2L1, TUD-Stadtmitte):
        # noise, which would only jostle the particles.
        height, width = frame.shape[:2]
        frame_corners = np.array([[0, 0, 1], [width, 0, 1], [0, height, 1], [width, height, 1]])
        moves = frame_corners @ similarity.T - frame_corners[:, :2]
        if np.max(np.hypot(moves[:, 0], moves[:, 1])) < _MIN_MOTION:
            return None
        return similarity


def warp_roots(particles: np.ndarray, motion: np.ndarray) -> None:
    """Move root states ``(..., 5)`` in place by the camera's ``motion`` (``2 x 3``
    similarity): centres mapped, velocities rotated and scaled, log heights shifted by the
    log of the scale."""
    linear, shift = motion[:, :2], motion[:, 2]
    particles[..., [CX, CY]] = particles[..., [CX, CY]] @ linear.T + shift
    particles[..., [VX, VY]] = particles[..., [VX, VY]] @ linear.T
    particles[..., LOG_H] += math.log(math.sqrt(abs(np.linalg.det(linear))))


def warp_boxes(boxes: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Boxes ``(N, 4)`` ``x, y, w, h`` moved by ``motion``: centres mapped, sizes scaled."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scale = math.sqrt(abs(np.linalg.det(motion[:, :2])))
    centres = (boxes[:, :2] + boxes[:, 2:] / 2) @ motion[:, :2].T + motion[:, 2]
    sizes = boxes[:, 2:] * scale
    return np.hstack([centres - sizes / 2, sizes])
