"""The person's root motion (docs/architecture.md §5, transition): constant velocity in the image
with the real time step, a random walk on log height, process noise proportional to the height."""

from __future__ import annotations

import numpy as np

# Columns of the root state: centre x, centre y (pixels), log height, velocity x, y (pixels/s).
CX, CY, LOG_H, VX, VY = range(5)
ROOT_DIM = 5

PEDESTRIAN_ASPECT = 0.41
"""Width / height of a standing person's box (Dollar, Wojek, Schiele, Perona, PAMI 2012, who
normalise every pedestrian box to it for evaluation): boxes are compared at this aspect."""


def propagate(
    particles: np.ndarray,
    dt: np.ndarray,
    noise_gain: np.ndarray,
    rng: np.random.Generator,
    *,
    position_noise: float,
    velocity_damping: float,
    log_height_noise: float,
) -> np.ndarray:
    """Sample every particle's root state ``dt`` seconds later.

    ``v' = damping^dt v + sigma_a h sqrt(dt) e``,   ``c' = c + v' dt``,
    ``log h' = log h + sigma_h sqrt(dt) e``.

    Parameters
    ----------
    particles:
        ``(T, N, 5)`` root states of ``T`` people.
    dt:
        ``(T,)`` seconds since each person's last frame (the real step: skipped stream frames
        just make it longer).
    noise_gain:
        ``(T,)`` factor on the process noise (larger while a person is occluded).
    """
    dt = np.maximum(np.asarray(dt, dtype=np.float64), 0.0)[:, None]
    gain = np.asarray(noise_gain, dtype=np.float64)[:, None]
    out = particles.copy()
    height = np.exp(particles[..., LOG_H])
    root_dt = np.sqrt(dt)
    shock = rng.standard_normal((*particles.shape[:2], 3))
    damping = velocity_damping**dt
    sigma_v = position_noise * height * root_dt * gain
    out[..., VX] = damping * particles[..., VX] + sigma_v * shock[..., 0]
    out[..., VY] = damping * particles[..., VY] + sigma_v * shock[..., 1]
    out[..., CX] = particles[..., CX] + out[..., VX] * dt
    out[..., CY] = particles[..., CY] + out[..., VY] * dt
    out[..., LOG_H] = particles[..., LOG_H] + log_height_noise * root_dt * gain * shock[..., 2]
    return out


def boxes_from_roots(roots: np.ndarray, aspect: np.ndarray) -> np.ndarray:
    """Boxes ``(..., 4)`` x, y, w, h from root states ``(..., 5)`` and width/height ratios."""
    height = np.exp(roots[..., LOG_H])
    width = height * aspect
    return np.stack(
        [roots[..., CX] - width / 2, roots[..., CY] - height / 2, width, height], axis=-1
    )


def with_aspect(boxes: np.ndarray, aspect: float = PEDESTRIAN_ASPECT) -> np.ndarray:
    """Boxes ``(N, 4)`` x, y, w, h of the same centre and height with width ``aspect * h``.

    The tracker reports its boxes so (``PeopleTrackerConfig.box_aspect``) and compares
    detections with predictions so (a detector's box width follows the arms and the stride,
    not the body); the fair MOT benchmark passes the peers' boxes through this same function.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    width = aspect * boxes[:, 3]
    return np.stack(
        [boxes[:, 0] + (boxes[:, 2] - width) / 2, boxes[:, 1], width, boxes[:, 3]], axis=1
    )
