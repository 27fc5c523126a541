"""Particle-filter building blocks (thesis appendix A.3): pure functions on weight arrays."""

from __future__ import annotations

import numpy as np


def normalize_log_weights(log_weights: np.ndarray) -> np.ndarray:
    """Normalised weights from log weights, along the last axis, without overflow.

    An all ``-inf`` row (every particle impossible) falls back to uniform weights: the filter
    keeps its spread instead of dividing by zero.
    """
    peak = np.max(log_weights, axis=-1, keepdims=True)
    peak = np.where(np.isfinite(peak), peak, 0.0)
    weights = np.exp(log_weights - peak)
    total = weights.sum(axis=-1, keepdims=True)
    uniform = np.full_like(weights, 1.0 / weights.shape[-1])
    return np.where(total > 0, weights / np.where(total > 0, total, 1.0), uniform)


def effective_sample_size(weights: np.ndarray) -> np.ndarray:
    """``1 / sum_i w_i^2`` of normalised weights, along the last axis."""
    return 1.0 / np.sum(weights**2, axis=-1)


def systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices of a systematic resampling of each row of ``weights`` (``(..., N)``).

    One uniform offset per row, ``N`` evenly spaced pointers into the cumulative weights: lower
    variance than multinomial resampling, ``O(N)`` per row.
    """
    n = weights.shape[-1]
    cumulative = np.cumsum(weights, axis=-1)
    cumulative[..., -1] = 1.0  # guard against rounding below 1
    offsets = rng.random((*weights.shape[:-1], 1))
    pointers = (np.arange(n) + offsets) / n
    # Row r's cumulative weights lie in (r, r + 1] once r is added, so all rows search one
    # sorted array at once.
    rows = np.arange(cumulative.size // n)[:, None]
    flat_c = (cumulative.reshape(-1, n) + rows).ravel()
    flat_p = (pointers.reshape(-1, n) + rows).ravel()
    indices = np.searchsorted(flat_c, flat_p).reshape(-1, n) - rows * n
    return np.minimum(indices, n - 1).reshape(weights.shape)
