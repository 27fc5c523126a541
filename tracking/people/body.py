"""The body model: where a person's parts sit relative to the root box, as Gaussian priors.

A part's offset ``d`` from the box centre is measured in person heights, so
``position = centre + height * d`` is linear in ``d`` given the root: what lets the particle
filter carry parts in Kalman filters (DESIGN.md §5).
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
    """

    names: tuple[str, ...]
    mean: np.ndarray
    std: np.ndarray
    size: np.ndarray

    def __post_init__(self) -> None:
        p = len(self.names)
        for name in ("mean", "std", "size"):
            if getattr(self, name).shape != (p, 2):
                raise ValueError(
                    f"{name} must have shape ({p}, 2), got {getattr(self, name).shape}"
                )
        if np.any(self.std <= 0):
            raise ValueError("part standard deviations must be positive")

    def __len__(self) -> int:
        return len(self.names)


def deformation_prior(quadratic: np.ndarray, linear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Gaussian a DPM deformation cost stands for (DESIGN.md §5, model likelihood).

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
)
"""The body model used when the detector has no parts of its own."""
