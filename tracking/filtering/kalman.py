"""Kalman filter steps for batches of independent linear-Gaussian states (thesis appendix A.2).

Every function takes leading batch dimensions ``(...)``: one call runs the filters of all
particles, parts and people at once.
"""

from __future__ import annotations

import numpy as np


def kalman_predict(
    mean: np.ndarray, cov: np.ndarray, transition: np.ndarray, noise: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Time update: ``x <- F x``, ``P <- F P F^T + Q``.

    Parameters
    ----------
    mean:
        ``(..., d)`` state means.
    cov:
        ``(..., d, d)`` state covariances.
    transition:
        ``F``, ``(d, d)`` or broadcastable to ``(..., d, d)``.
    noise:
        ``Q``, ``(d, d)`` or broadcastable to ``(..., d, d)``.
    """
    if mean.shape[-1] == 1:  # 1x1 matrices: the products are elementwise
        transition = np.asarray(transition)
        return transition[..., 0] * mean, transition * cov * transition + noise
    mean = np.einsum("...ij,...j->...i", transition, mean)  # x = F x
    cov = transition @ cov @ np.swapaxes(transition, -1, -2) + noise  # P = F P F' + Q
    return mean, cov


def kalman_update(
    mean: np.ndarray,
    cov: np.ndarray,
    measurement: np.ndarray,
    observation: np.ndarray,
    noise: np.ndarray,
    offset: np.ndarray | float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Measurement update for ``z = H x + c + v``, ``v ~ N(0, R)``, and its marginal likelihood.

    Parameters
    ----------
    mean, cov:
        ``(..., d)`` and ``(..., d, d)``.
    measurement:
        ``z``, ``(..., m)``.
    observation:
        ``H``, ``(..., m, d)`` (broadcastable).
    noise:
        ``R``, ``(..., m, m)`` (broadcastable).
    offset:
        ``c``, ``(..., m)`` (broadcastable): the part of the prediction that does not depend on
        ``x`` (the root position, for a body part).

    Returns
    -------
    mean, cov, log_likelihood
        The updated state and ``log N(z; H x + c, H P H^T + R)``, ``(...)``: the evidence a
        particle filter weighs its particles by (eq. A.16 of the RBPF).
    """
    if mean.shape[-1] == 1 and np.shape(measurement)[-1] == 1:
        return _scalar_update(mean, cov, measurement, observation, noise, offset)
    h_t = np.swapaxes(observation, -1, -2)
    innovation = measurement - (np.einsum("...ij,...j->...i", observation, mean) + offset)
    s = observation @ cov @ h_t + noise  # S = H P H' + R
    s_inv = np.linalg.inv(s)
    gain = cov @ h_t @ s_inv  # K = P H' S^-1
    mean = mean + np.einsum("...ij,...j->...i", gain, innovation)  # x = x + K (z - H x - c)
    cov = cov - gain @ observation @ cov  # P = (I - K H) P
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))  # keep it symmetric against rounding
    m = innovation.shape[-1]
    mahalanobis = np.einsum("...i,...ij,...j->...", innovation, s_inv, innovation)
    log_det = np.linalg.slogdet(s)[1]
    log_likelihood = -0.5 * (mahalanobis + log_det + m * np.log(2.0 * np.pi))
    return mean, cov, log_likelihood


def _scalar_update(
    mean: np.ndarray,
    cov: np.ndarray,
    measurement: np.ndarray,
    observation: np.ndarray,
    noise: np.ndarray,
    offset: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kalman_update` of 1-D states and measurements: the same formulas with every
    1x1 matrix a number, elementwise (a tenth of the time of the stacked matrix products)."""
    p, h, r = cov[..., 0], np.asarray(observation)[..., 0], np.asarray(noise)[..., 0]
    innovation = measurement - (h * mean + offset)
    s = h * p * h + r  # S = H P H' + R
    gain = p * h / s  # K = P H' S^-1
    mean = mean + gain * innovation
    p = p - gain * h * p  # P = (I - K H) P
    log_likelihood = -0.5 * (innovation**2 / s + np.log(s) + np.log(2.0 * np.pi))
    return mean, p[..., None], log_likelihood[..., 0]
