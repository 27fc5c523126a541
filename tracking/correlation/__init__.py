"""Circulant-structure trackers of thesis Part I: MOSSE, CSK and the proposed RCSK."""

from tracking.correlation.config import CorrelationConfig, ScaleConfig
from tracking.correlation.presets import COLOR_FEATURES, PRESETS
from tracking.correlation.tracker import CorrelationTracker

__all__ = ["COLOR_FEATURES", "PRESETS", "CorrelationConfig", "CorrelationTracker", "ScaleConfig"]
