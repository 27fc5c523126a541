"""Circulant-structure trackers of thesis Part I: MOSSE, CSK and the proposed RCSK."""

from __future__ import annotations

from typing import TYPE_CHECKING

from tracking.correlation.config import CorrelationConfig, ScaleConfig
from tracking.correlation.presets import COLOR_FEATURES, DEFAULT_PRESET, PRESETS

if TYPE_CHECKING:
    from tracking.correlation.tracker import CorrelationTracker

__all__ = [
    "COLOR_FEATURES",
    "DEFAULT_PRESET",
    "PRESETS",
    "CorrelationConfig",
    "CorrelationTracker",
    "ScaleConfig",
]


def __getattr__(name: str) -> object:
    # The tracker pulls in numba and the feature maps (about half a second): loaded on first
    # use, so that reading the presets (``vtrack``'s argument parser) does not wait for them.
    if name == "CorrelationTracker":
        from tracking.correlation.tracker import CorrelationTracker

        return CorrelationTracker
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
