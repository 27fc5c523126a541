"""Named configurations: the thesis's tracker variants and ours for embedded defaults.

Every preset is a :class:`CorrelationConfig`; change a field with :func:`dataclasses.replace`.
"""

from __future__ import annotations

from types import MappingProxyType

from tracking.correlation.config import CorrelationConfig, ScaleConfig

# The colour representations of §3.1, each evaluated with the proposed RCSK (§5.3). Each one is
# used beside grayscale, as the proposed tracker uses Color Names ("gray+cn"), so that the
# comparison isolates what the colour representation adds.
COLOR_FEATURES = (
    "gray",
    "rgb",
    "lab",
    "ycbcr",
    "rg",
    "hsv",
    "opponent",
    "c",
    "hue",
    "opp_angle",
    "so",
    "cn",
)


def _presets() -> dict[str, CorrelationConfig]:
    presets = {
        # §5.2: the learning schemes on grayscale and on grayscale + Color Names.
        "mosse_gray": CorrelationConfig(learner="mosse", feature="gray"),
        "csk_gray": CorrelationConfig(learner="csk", feature="gray"),
        "rcsk_gray": CorrelationConfig(learner="rcsk", feature="gray"),
        "csk_cn": CorrelationConfig(learner="csk", feature="gray+cn"),
        "rcsk_cn": CorrelationConfig(learner="rcsk", feature="gray+cn"),
        # §5.4: the adaptive dimensionality reduction of gray + Color Names to 2 dimensions.
        "rcsk_cn_pca2": CorrelationConfig(learner="rcsk", feature="gray+cn", compressed_dim=2),
    }
    for colour in COLOR_FEATURES:
        feature = "gray" if colour == "gray" else f"gray+{colour}"
        presets.setdefault(f"rcsk_{colour}", CorrelationConfig(learner="rcsk", feature=feature))
    # Ours, beyond the thesis: HOG beside Color Names on 4-pixel cells, the patch capped at
    # 6400 pixels (at most 20 x 20 cells, so the cost no longer grows with the target) and
    # enlarged to at least 64 pixels (16 cells) along its short side for small targets, and the
    # scale filter on cheap grayscale samples. Chosen on temporal-robustness runs (each OTB
    # sequence started at 0, 1/3 and 2/3) rather than on single runs, whose AUC swings by 0.2
    # when one track is lost; see docs/benchmarks.md.
    presets["hog_cn_scale"] = CorrelationConfig(
        learner="rcsk",
        feature="hog+cn",
        cell_size=4,
        padding=1.5,
        learning_rate=0.02,
        label_sigma=0.1,
        kernel_sigma=0.5,
        max_patch_area=6400,
        min_patch_side=64,
        scale=ScaleConfig(feature="gray"),
    )
    # The product default (issue 77): STRCF (Li et al. 2018) with its reference settings but
    # one: grey, HOG and Color Names on 4-pixel cells, a square search region of 5 x 5 target
    # areas sampled at 150-200 pixels a side, two ADMM iterations, 5 scales 1% apart. ECO-HC's
    # factorised convolution (HOG to 10 channels, Color Names to 3) and the search scales
    # zoomed on the feature grid make it 3-4x CSRT's speed. The failure signal is LMCF's peak
    # test at the paper's 0.45 (its APCE test flagged a third of the frames of the tuning runs,
    # half of them well tracked, and cost 0.03 AUC). The temporal regularisation mu is the one
    # constant fitted here, since it weighs against the features' energy, which differs from
    # the reference's: over mu 0.5-40 the mean AUC of the tuning runs (five starts in each of
    # the first five OTB sequences) peaks on a plateau at 2-5 (0.68-0.70, against 0.65 at the
    # paper's 15) and we take its more regularised end. Every choice was made on those runs;
    # the five sequences added later confirmed it (docs/benchmarks.md).
    presets["strcf_hog_cn"] = CorrelationConfig(
        learner="strcf",
        feature="gray+hog+cn",
        cell_size=4,
        padding=4.0,
        square_patch=True,
        label_sigma=1.0 / 16.0,
        max_patch_area=200 * 200,
        min_patch_side=150,
        compressed_features=(("hog", 10), ("cn", 3)),
        search_scales=5,
        search_scale_step=1.01,
        temporal_regularization=5.0,
        peak_ratio=0.45,
    )
    return presets


PRESETS = MappingProxyType(_presets())
"""Read-only mapping from preset name to configuration."""

DEFAULT_PRESET = "strcf_hog_cn"
"""The preset of single-target jobs and ``vtrack track`` (``api_schemas.jobs`` names it too)."""
