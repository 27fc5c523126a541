"""The Rao-Blackwellized particle filter (thesis appendix A.4; Schön, Gustafsson, Nordlund 2005).

The state splits into a non-linear part ``x^n``, sampled by particles, and a linear part ``x^l``
that is linear-Gaussian given ``x^n`` and is therefore carried by one Kalman filter per particle:

    x^n_{t+1} = f(x^n_t) + v^n                                (any model, sampled)
    x^l_{t+1} = A x^l_t + w^l,            w^l ~ N(0, Q)
    y_t       ~ p(y_t | x^n_t)                                (any likelihood of x^n)
    z_t       = H(x^n_t) x^l_t + c(x^n_t) + e_t,   e_t ~ N(0, R)

Here ``x^n`` does not depend on ``x^l`` (a person's root moves whatever its parts do), which is
the case where the filter needs no extra "measurement" of ``x^l`` from the motion of ``x^n``.
The linear part is a set of ``K`` independent blocks (one per body part): with block-diagonal
``A``, ``Q``, ``H`` and ``R`` the joint Kalman filter splits into ``K`` small ones exactly, so the
cost grows linearly in ``K``.

Every array carries any number of leading batch axes ``(...)`` (people), then the particle axis:
one call filters every particle of every person. Functions are pure: they return a new state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from tracking.filtering.kalman import kalman_predict, kalman_update
from tracking.filtering.particles import (
    effective_sample_size,
    normalize_log_weights,
    systematic_resample,
)


@dataclass(frozen=True, slots=True)
class RbpfState:
    """Particles and their Kalman filters.

    Attributes
    ----------
    particles:
        ``(..., N, dn)`` non-linear states.
    weights:
        ``(..., N)`` normalised importance weights.
    mean:
        ``(..., N, K, dl)`` linear-state means, one per particle and block.
    cov:
        ``(..., N, K, dl, dl)`` their covariances.
    """

    particles: np.ndarray
    weights: np.ndarray
    mean: np.ndarray
    cov: np.ndarray

    @classmethod
    def from_prior(
        cls,
        particles: np.ndarray,
        mean: np.ndarray,
        cov: np.ndarray,
    ) -> RbpfState:
        """Equal weights; ``mean`` ``(K, dl)`` and ``cov`` ``(K, dl, dl)`` copied to every
        particle (or already ``(..., N, K, ...)``)."""
        n = particles.shape[-2]
        batch = particles.shape[:-1]
        mean = np.broadcast_to(mean, (*batch, *mean.shape[-2:])).copy()
        cov = np.broadcast_to(cov, (*batch, *cov.shape[-3:])).copy()
        return cls(particles, np.full(batch, 1.0 / n), mean, cov)


def predict(
    state: RbpfState,
    propagate: Callable[[np.ndarray], np.ndarray],
    transition: np.ndarray,
    noise: np.ndarray,
) -> RbpfState:
    """Time update: sample ``x^n_{t+1}`` with ``propagate`` and Kalman-predict ``x^l``.

    Parameters
    ----------
    propagate:
        Maps particles ``(..., N, dn)`` to their samples at the next time (noise included).
    transition, noise:
        ``A`` and ``Q`` of the linear blocks: ``(dl, dl)`` or broadcastable to
        ``(..., N, K, dl, dl)`` (per block, or per person for a person-dependent time step).
    """
    mean, cov = kalman_predict(state.mean, state.cov, transition, noise)
    return replace(state, particles=propagate(state.particles), mean=mean, cov=cov)


def update(
    state: RbpfState,
    log_likelihood: np.ndarray | None = None,
    *,
    blocks: np.ndarray | None = None,
    measurement: np.ndarray | None = None,
    observation: np.ndarray | None = None,
    offset: np.ndarray | float = 0.0,
    noise: np.ndarray | None = None,
    evidence_weight: float = 1.0,
) -> RbpfState:
    """Measurement update: weigh the particles, then Kalman-update the measured blocks.

    The weight of particle ``i`` is multiplied by ``p(y | x^n_i)`` (``log_likelihood``) and by
    the marginal likelihood of each block measurement under that particle's Kalman filter,
    ``N(z_k; H_i m_ik + c_i, H_i P_ik H_i^T + R_k)``.

    Parameters
    ----------
    log_likelihood:
        ``(..., N)`` ``log p(y | x^n)``, or ``None``.
    blocks:
        ``(..., M)`` integer indices of the measured blocks (``None``: no block measurement).
        A batch row may repeat or pad indices only together with ``noise = inf`` on the padding
        (an infinite noise carries no information and leaves that block and the weight alone).
    measurement:
        ``(..., M, m)`` the measurements ``z_k``.
    observation:
        ``H`` broadcastable to ``(..., N, M, m, dl)``.
    offset:
        ``c`` broadcastable to ``(..., N, M, m)``.
    noise:
        ``R`` broadcastable to ``(..., N, M, m, m)``.
    evidence_weight:
        Exponent on the block measurements' marginal likelihoods in the weights: 1 (default)
        is the Rao-Blackwellized update; 0 updates each particle's Kalman filters without
        letting those measurements move the particles' weights (the root is then weighed by
        ``log_likelihood`` alone); values between temper the evidence.
    """
    log_w = np.log(np.maximum(state.weights, 1e-300))
    if log_likelihood is not None:
        log_w = log_w + log_likelihood
    mean, cov = state.mean, state.cov
    if blocks is not None and blocks.shape[-1] > 0:
        if measurement is None or observation is None or noise is None:
            raise ValueError("blocks need their measurement, observation and noise")
        index = np.broadcast_to(blocks[..., None, :], (*state.weights.shape, blocks.shape[-1]))
        # every block in its order (the pose network's keypoints, one slot per part): the
        # blocks are the filters themselves, with no gather and scatter
        in_order = index.shape[-1] == mean.shape[-2] and bool(
            np.all(index == np.arange(mean.shape[-2]))
        )
        if in_order:
            picked_mean, picked_cov = mean, cov
        else:
            picked_mean = np.take_along_axis(mean, index[..., None], axis=-2)
            picked_cov = np.take_along_axis(cov, index[..., None, None], axis=-3)
        z = np.expand_dims(measurement, -3)  # one measurement for every particle
        informative = np.all(np.isfinite(noise), axis=(-1, -2))
        safe_noise = np.where(np.isfinite(noise), noise, 1.0)
        new_mean, new_cov, log_evidence = kalman_update(
            picked_mean, picked_cov, z, observation, safe_noise, offset
        )
        informative = np.broadcast_to(informative, log_evidence.shape)
        log_w = log_w + evidence_weight * np.sum(np.where(informative, log_evidence, 0.0), axis=-1)
        new_mean = np.where(informative[..., None], new_mean, picked_mean)
        new_cov = np.where(informative[..., None, None], new_cov, picked_cov)
        if in_order:
            mean, cov = new_mean, new_cov
        else:
            mean, cov = mean.copy(), cov.copy()
            np.put_along_axis(mean, index[..., None], new_mean, axis=-2)
            np.put_along_axis(cov, index[..., None, None], new_cov, axis=-3)
    return replace(state, weights=normalize_log_weights(log_w), mean=mean, cov=cov)


def resample(state: RbpfState, rng: np.random.Generator, threshold: float = 0.5) -> RbpfState:
    """Systematic resampling of the rows whose effective sample size is below
    ``threshold * N``; the others are left as they are."""
    n = state.weights.shape[-1]
    needed = effective_sample_size(state.weights) < threshold * n
    if not np.any(needed):
        return state
    indices = systematic_resample(state.weights, rng)
    keep = np.broadcast_to(np.arange(n), indices.shape)
    indices = np.where(needed[..., None], indices, keep)
    weights = np.where(needed[..., None], 1.0 / n, state.weights)
    return RbpfState(
        _gather(state.particles, indices, 1),
        weights,
        _gather(state.mean, indices, 2),
        _gather(state.cov, indices, 3),
    )


def _gather(values: np.ndarray, indices: np.ndarray, trailing: int) -> np.ndarray:
    """``values[..., indices, <trailing axes>]`` along the particle axis."""
    index = indices.reshape(indices.shape + (1,) * trailing)
    return np.take_along_axis(values, index, axis=-1 - trailing)


def estimate(state: RbpfState) -> tuple[np.ndarray, np.ndarray]:
    """Minimum mean-square estimates (thesis A.4.2): the weighted mean of the particles
    ``(..., dn)`` and of the linear means ``(..., K, dl)``."""
    w = state.weights
    nonlinear = np.einsum("...n,...nd->...d", w, state.particles)
    linear = np.einsum("...n,...nkd->...kd", w, state.mean)
    return nonlinear, linear
