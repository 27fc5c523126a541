"""Feature extraction for the correlation trackers: colour representations (thesis chapter 3).

Use :class:`FeatureExtractor` with a name from :data:`FEATURE_NAMES` (or ``"gray+cn"``, the
thesis's main configuration); the per-representation functions and the Color Names table are
exported for direct use.
"""

from tracking.features.colornames import (
    COLOR_NAMES,
    N_COLOR_BINS,
    ColorNamesError,
    ColorNameTable,
    TseParameterSet,
    load_w2c_table,
    tse_color_names,
    zero_sum_basis,
)
from tracking.features.colorspaces import (
    HUE_BINS,
    SO_SCALES,
    SO_SURROUND_RATIO,
    c_features,
    gray_features,
    hsv_features,
    hue_features,
    lab_features,
    opp_angle_features,
    opponent_features,
    rg_features,
    rgb_features,
    so_features,
    ycbcr_features,
)
from tracking.features.registry import FEATURE_NAMES, FeatureExtractor, FeatureSpec, feature_dim

__all__ = [
    "COLOR_NAMES",
    "FEATURE_NAMES",
    "HUE_BINS",
    "N_COLOR_BINS",
    "SO_SCALES",
    "SO_SURROUND_RATIO",
    "ColorNameTable",
    "ColorNamesError",
    "FeatureExtractor",
    "FeatureSpec",
    "TseParameterSet",
    "c_features",
    "feature_dim",
    "gray_features",
    "hsv_features",
    "hue_features",
    "lab_features",
    "load_w2c_table",
    "opp_angle_features",
    "opponent_features",
    "rg_features",
    "rgb_features",
    "so_features",
    "tse_color_names",
    "ycbcr_features",
    "zero_sum_basis",
]
