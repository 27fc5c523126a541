"""Measurement likelihoods of the root state (docs/architecture.md §5), vectorized over
particles."""

from __future__ import annotations

import numpy as np

from tracking.people.motion import CX, CY, LOG_H


def detection_log_likelihood(
    particles: np.ndarray,
    box: np.ndarray,
    probability: float,
    *,
    sigma: tuple[float, float],
    log_height_sigma: float,
    clutter: float,
) -> np.ndarray:
    """``log p(detection | root)`` for each particle, for detectors without dense scores.

    The detection's centre is Gaussian about the particle's centre with standard deviations of
    ``sigma = (sx, sy)`` heights, its log height Gaussian about the particle's; a detection that
    is right with probability ``probability`` (its calibrated score) and clutter otherwise gives
    the mixture ``p N(...) + clutter``, so one wrong association cannot wipe out every particle.

    Parameters
    ----------
    particles:
        ``(N, 5)`` root states.
    box:
        The detection, ``x, y, w, h``.
    """
    height = np.exp(particles[:, LOG_H])
    det_cx, det_cy = box[0] + box[2] / 2.0, box[1] + box[3] / 2.0
    d2 = ((particles[:, CX] - det_cx) / (sigma[0] * height)) ** 2
    d2 += ((particles[:, CY] - det_cy) / (sigma[1] * height)) ** 2
    d2 += ((particles[:, LOG_H] - np.log(box[3])) / log_height_sigma) ** 2
    # The 2-D position density carries 1 / (sx sy h^2); relative to a particle of the detection's
    # own height, so that the peak is about 1 whatever the person's size.
    density = np.exp(-0.5 * d2) * (box[3] / height) ** 2
    return np.log(probability * density + clutter)


def predictive_log_likelihood(
    particles: np.ndarray,
    boxes: np.ndarray,
    *,
    sigma: tuple[float, float],
    log_height_sigma: float,
) -> np.ndarray:
    """``log p(detection j | person i's predicted particles)`` for every pair: the Gaussian
    density of :func:`detection_log_likelihood` (without its clutter term) averaged over the
    person's particles, i.e. the Monte-Carlo predictive likelihood that associating detection
    ``j`` with person ``i`` should be judged by.

    Parameters
    ----------
    particles:
        ``(T, N, 5)`` predicted root states of ``T`` people.
    boxes:
        ``(D, 4)`` detections ``x, y, w, h``.

    Returns
    -------
    ``(T, D)`` log likelihoods.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    p = particles[:, :, None, :]  # (T, N, 1, 5)
    height = np.exp(p[..., LOG_H])
    d2 = ((p[..., CX] - (boxes[:, 0] + boxes[:, 2] / 2)) / (sigma[0] * height)) ** 2
    d2 += ((p[..., CY] - (boxes[:, 1] + boxes[:, 3] / 2)) / (sigma[1] * height)) ** 2
    d2 += ((p[..., LOG_H] - np.log(boxes[:, 3])) / log_height_sigma) ** 2
    log_density = -0.5 * d2 + 2.0 * (np.log(boxes[:, 3]) - p[..., LOG_H])
    n = particles.shape[1]
    return np.logaddexp.reduce(log_density, axis=1) - np.log(n)


def dense_score_log_likelihood(
    scores: np.ndarray, calibration_slope: float, calibration_offset: float
) -> np.ndarray:
    """``log p(scores | root)`` from a detector's raw scores at the particles: the calibrated
    probability of a person there, ``sigmoid(a s + b)`` (thesis ch. 7.2.2: scores turned into
    likelihoods by a calibrated mapping). Positions the detector could not score (``-inf``)
    get the floor of a clear miss."""
    z = calibration_slope * np.nan_to_num(scores, neginf=-50.0) + calibration_offset
    return -np.logaddexp(0.0, -z)  # log sigmoid(z)
