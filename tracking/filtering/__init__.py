"""Bayesian filters: batched Kalman steps, particle-filter blocks, the Rao-Blackwellized
particle filter (thesis appendix A)."""

from tracking.filtering.kalman import kalman_predict, kalman_update
from tracking.filtering.particles import (
    effective_sample_size,
    normalize_log_weights,
    systematic_resample,
)
from tracking.filtering.rbpf import RbpfState, estimate, predict, resample, update

__all__ = [
    "RbpfState",
    "effective_sample_size",
    "estimate",
    "kalman_predict",
    "kalman_update",
    "normalize_log_weights",
    "predict",
    "resample",
    "systematic_resample",
    "update",
]
