"""The body model: where a person's parts sit relative to the root box, as Gaussian priors.

A part's offset ``d`` from the box centre is measured in person heights, so
``position = centre + height * d`` is linear in ``d`` given the root: what lets the particle
filter carry parts in Kalman filters (docs/architecture.md §5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class BodyModel:
    """Named parts with Gaussian priors on their offsets.

    Attributes
    ----------
    names:
        ``P`` part names (left and right are the image's, as in
        :mod:`tracking.detection.dpm.parts`).
    mean:
        ``(P, 2)`` mean offsets ``(dx, dy)`` from the box centre, in heights.
    std:
        ``(P, 2)`` standard deviations of the offsets about the mean, in heights.
    size:
        ``(P, 2)`` width and height of each part's box, in heights.
    skeleton:
        Pairs of part names joined by a limb, for drawing (an empty tuple: none).
    """

    names: tuple[str, ...]
    mean: np.ndarray
    std: np.ndarray
    size: np.ndarray
    skeleton: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        p = len(self.names)
        for name in ("mean", "std", "size"):
            if getattr(self, name).shape != (p, 2):
                raise ValueError(
                    f"{name} must have shape ({p}, 2), got {getattr(self, name).shape}"
                )
        if np.any(self.std <= 0):
            raise ValueError("part standard deviations must be positive")
        unknown = {name for edge in self.skeleton for name in edge} - set(self.names)
        if unknown or any(len(edge) != 2 for edge in self.skeleton):
            raise ValueError(f"skeleton must join pairs of the parts, not {sorted(unknown)}")

    def __len__(self) -> int:
        return len(self.names)


def deformation_prior(quadratic: np.ndarray, linear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussian a DPM deformation cost stands for (docs/architecture.md §5, model likelihood).

    A placement cost ``a dx^2 + b dx`` (per axis, ``a > 0``) is ``-log`` of a Gaussian up to a
    constant: ``a (dx + b / 2a)^2 + const``, so ``exp(-cost)`` has mean ``-b / (2a)`` and variance
    ``1 / (2a)``.

    Returns
    -------
    mean, variance
        Arrays shaped like the inputs.
    """
    quadratic = np.asarray(quadratic, dtype=np.float64)
    if np.any(quadratic <= 0):
        raise ValueError("deformation quadratic weights must be positive")
    return -np.asarray(linear, dtype=np.float64) / (2.0 * quadratic), 1.0 / (2.0 * quadratic)


# Segment proportions of an upright adult (Drillis & Contini 1966, as tabulated by Winter,
# "Biomechanics and Motor Control of Human Movement"): heights of the joints from the floor as
# shares of body height (head centre 0.94, shoulders 0.818, hips 0.530, knees 0.285, ankles 0.039)
# and half-widths (shoulders 0.129, hips 0.095, knees and feet 0.07). The box centre is at half
# height, so dy = 0.5 - joint height.
_EMBEDDED = (
    # name,            dx,     dy,     std x, std y, box w, box h
    ("head", 0.0, -0.44, 0.02, 0.015, 0.13, 0.13),
    ("left_shoulder", -0.11, -0.318, 0.025, 0.02, 0.12, 0.12),
    ("right_shoulder", 0.11, -0.318, 0.025, 0.02, 0.12, 0.12),
    ("left_hip", -0.08, -0.03, 0.025, 0.025, 0.12, 0.12),
    ("right_hip", 0.08, -0.03, 0.025, 0.025, 0.12, 0.12),
    ("left_knee", -0.07, 0.215, 0.04, 0.03, 0.11, 0.12),
    ("right_knee", 0.07, 0.215, 0.04, 0.03, 0.11, 0.12),
    ("left_foot", -0.07, 0.45, 0.06, 0.03, 0.11, 0.1),
    ("right_foot", 0.07, 0.45, 0.06, 0.03, 0.11, 0.1),
)

EMBEDDED_BODY = BodyModel(
    names=tuple(row[0] for row in _EMBEDDED),
    mean=np.array([row[1:3] for row in _EMBEDDED]),
    std=np.array([row[3:5] for row in _EMBEDDED]),
    size=np.array([row[5:7] for row in _EMBEDDED]),
    skeleton=(
        ("head", "left_shoulder"),
        ("head", "right_shoulder"),
        ("left_shoulder", "right_shoulder"),
        ("left_shoulder", "left_hip"),
        ("right_shoulder", "right_hip"),
        ("left_hip", "right_hip"),
        ("left_hip", "left_knee"),
        ("right_hip", "right_knee"),
        ("left_knee", "left_foot"),
        ("right_knee", "right_foot"),
    ),
)
"""The body model used when the detector has no parts of its own."""

# The pose network's 18 keypoints (tracking.detection.pose.KEYPOINT_NAMES; left and right are
# the person's own, as in COCO) with the same proportions: joint heights from the floor as
# shares of body height (Drillis & Contini via Winter: eyes 0.936, ears 0.92, nose 0.91, neck
# and shoulders 0.818, elbows 0.630, wrists 0.485, hips 0.530, knees 0.285, ankles 0.039).
# Whether a person's own left shoulder lies left or right in the image depends on which way
# they face, so a paired joint's mean across is 0 and its spread the joint's half-width
# (shoulders 0.129, elbows 0.15, wrists 0.15, hips 0.095, knees and ankles 0.07; eyes 0.03,
# ears 0.07): the keypoints that measure it say which side it is on.
_POSE = (
    # name,            dy,     std x, std y, box side
    ("nose", -0.41, 0.03, 0.02, 0.06),
    ("neck", -0.318, 0.03, 0.02, 0.08),
    ("right_shoulder", -0.318, 0.129, 0.025, 0.08),
    ("right_elbow", -0.13, 0.15, 0.04, 0.07),
    ("right_wrist", 0.015, 0.15, 0.06, 0.06),
    ("left_shoulder", -0.318, 0.129, 0.025, 0.08),
    ("left_elbow", -0.13, 0.15, 0.04, 0.07),
    ("left_wrist", 0.015, 0.15, 0.06, 0.06),
    ("right_hip", -0.03, 0.095, 0.025, 0.08),
    ("right_knee", 0.215, 0.07, 0.03, 0.08),
    ("right_ankle", 0.461, 0.07, 0.03, 0.07),
    ("left_hip", -0.03, 0.095, 0.025, 0.08),
    ("left_knee", 0.215, 0.07, 0.03, 0.08),
    ("left_ankle", 0.461, 0.07, 0.03, 0.07),
    ("right_eye", -0.436, 0.03, 0.015, 0.04),
    ("left_eye", -0.436, 0.03, 0.015, 0.04),
    ("right_ear", -0.42, 0.07, 0.02, 0.05),
    ("left_ear", -0.42, 0.07, 0.02, 0.05),
)

POSE_BODY = BodyModel(
    names=tuple(row[0] for row in _POSE),
    mean=np.array([(0.0, row[1]) for row in _POSE]),
    std=np.array([row[2:4] for row in _POSE]),
    size=np.array([(row[4], row[4]) for row in _POSE]),
    skeleton=(
        ("neck", "right_shoulder"),
        ("neck", "left_shoulder"),
        ("right_shoulder", "right_elbow"),
        ("right_elbow", "right_wrist"),
        ("left_shoulder", "left_elbow"),
        ("left_elbow", "left_wrist"),
        ("neck", "right_hip"),
        ("right_hip", "right_knee"),
        ("right_knee", "right_ankle"),
        ("neck", "left_hip"),
        ("left_hip", "left_knee"),
        ("left_knee", "left_ankle"),
        ("neck", "nose"),
        ("nose", "right_eye"),
        ("right_eye", "right_ear"),
        ("nose", "left_eye"),
        ("left_eye", "left_ear"),
    ),
)
"""The body model of the pose network's keypoints (the tracker's parts when it runs one): the
17 limbs of OpenPose's tree as its skeleton."""
