"""Colour representations (`tracking.features.colorspaces`) and the feature registry."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tracking.features import colorspaces as cs
from tracking.features.colornames import ColorNameTable, zero_sum_basis
from tracking.features.registry import FEATURE_NAMES, FeatureExtractor, feature_dim

EXPECTED_DIMS = {
    "gray": 1,
    "rgb": 3,
    "lab": 3,
    "ycbcr": 3,
    "rg": 2,
    "hsv": 3,
    "opponent": 3,
    "c": 3,
    "hue": 36,
    "opp_angle": 36,
    "so": 12,
    "cn": 10,
    "gray+cn": 11,  # the thesis's main configuration
}


@pytest.fixture(scope="module")
def color_names() -> ColorNameTable:
    return ColorNameTable.embedded()


@pytest.fixture(scope="module")
def stress_image() -> np.ndarray:
    """Random pixels plus the extremes: black, white, primaries, hard edges, a black block."""
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    image[:8, :8] = 0
    image[:8, 8:16] = 255
    for i, colour in enumerate([(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0)]):
        image[8:16, 8 * i : 8 * i + 8] = colour
    image[16:24, ::2] = (255, 255, 255)  # one-pixel stripes: the strongest DoG responses
    image[16:24, 1::2] = (0, 0, 0)
    return image


def _flat(rgb: tuple[int, int, int], size: tuple[int, int] = (9, 11)) -> np.ndarray:
    return np.broadcast_to(np.array(rgb, np.uint8), (*size, 3)).copy()


# --- registry contract -------------------------------------------------------------------------


def test_feature_names_are_the_thesis_representations() -> None:
    assert tuple(name for name in EXPECTED_DIMS if "+" not in name) == FEATURE_NAMES


@pytest.mark.parametrize("name", list(EXPECTED_DIMS))
def test_every_feature_is_float32_hwd_finite_and_bounded(
    name: str, stress_image: np.ndarray, color_names: ColorNameTable
) -> None:
    extractor = FeatureExtractor(name, color_names)
    assert extractor.dim == EXPECTED_DIMS[name] == feature_dim(name)
    out = extractor(stress_image)
    assert out.dtype == np.float32
    assert out.shape == (*stress_image.shape[:2], EXPECTED_DIMS[name])
    assert np.isfinite(out).all()
    assert np.abs(out).max() <= 1.0


def test_gray_plus_cn_stacks_gray_then_cn(
    stress_image: np.ndarray, color_names: ColorNameTable
) -> None:
    out = FeatureExtractor("gray+cn", color_names)(stress_image)
    np.testing.assert_array_equal(out[..., :1], cs.gray_features(stress_image))
    np.testing.assert_array_equal(out[..., 1:], color_names(stress_image))


def test_cn_defaults_to_the_embedded_model() -> None:
    extractor = FeatureExtractor("cn")
    assert extractor.color_names is not None
    assert extractor.color_names.source == "tse:benavente2008"
    assert FeatureExtractor("rgb").color_names is None


@pytest.mark.parametrize("name", ["hog", "grey", "gray+nope", ""])
def test_unknown_names_list_the_valid_ones(name: str) -> None:
    with pytest.raises(ValueError, match="valid names are gray, rgb, lab"):
        FeatureExtractor(name)


def test_repeated_feature_is_rejected() -> None:
    with pytest.raises(ValueError, match="more than once"):
        FeatureExtractor("cn+cn")


@pytest.mark.parametrize("name", [n for n in EXPECTED_DIMS if n != "gray"])
@pytest.mark.parametrize("shape", [(20, 30), (20, 30, 1)])
def test_colour_features_reject_grayscale_frames(name: str, shape: tuple[int, ...]) -> None:
    frame = np.zeros(shape, np.uint8)
    expected = f"feature '{name}' needs an RGB frame (H, W, 3), got shape {shape}"
    with pytest.raises(ValueError, match=re.escape(expected)):
        FeatureExtractor(name)(frame)


@pytest.mark.parametrize("shape", [(20, 30), (20, 30, 1)])
def test_gray_accepts_grayscale_frames(shape: tuple[int, ...]) -> None:
    frame = np.random.default_rng(2).integers(0, 256, shape, dtype=np.uint8)
    out = FeatureExtractor("gray")(frame)
    assert out.shape == (20, 30, 1) and out.dtype == np.float32
    np.testing.assert_allclose(out[..., 0], frame.reshape(20, 30) / 255 - 0.5, atol=1e-6)


def test_non_uint8_frames_are_rejected() -> None:
    with pytest.raises(TypeError, match="uint8"):
        FeatureExtractor("rgb")(np.zeros((4, 4, 3), np.float32))


# --- normalisation claims (thesis §2.4.3, §3.2.1) ----------------------------------------------


def test_gray_of_mid_grey_is_about_zero() -> None:
    out = cs.gray_features(_flat((128, 128, 128)))
    np.testing.assert_allclose(out, 0.0, atol=1 / 255)


S2, S6 = math.sqrt(2), math.sqrt(6)


@pytest.mark.parametrize(
    ("function", "rgb", "expected", "atol"),
    [
        # gray and rgb: [0, 255] onto [-0.5, 0.5]
        (cs.gray_features, (0, 0, 0), [-0.5], 1e-6),
        (cs.gray_features, (255, 255, 255), [0.5], 1e-6),
        (cs.rgb_features, (255, 0, 0), [0.5, -0.5, -0.5], 1e-6),
        # lab: L* 0..100 onto ±0.5, a* = b* = 0 on the grey axis
        (cs.lab_features, (0, 0, 0), [-0.5, 0.0, 0.0], 1e-3),
        (cs.lab_features, (255, 255, 255), [0.5, 0.0, 0.0], 1e-3),
        # ycbcr: white is Y = 1 with neutral chroma
        (cs.ycbcr_features, (255, 255, 255), [0.5, 0.0, 0.0], 1e-3),
        # rg: the chromaticity of red is (1, 0); black is safely the achromatic point (1/3, 1/3)
        (cs.rg_features, (255, 0, 0), [0.5, -0.5], 1e-6),
        (cs.rg_features, (0, 0, 0), [1 / 3 - 0.5, 1 / 3 - 0.5], 1e-6),
        # hsv: blue is H = 240 deg, fully saturated, full value
        (cs.hsv_features, (0, 0, 255), [240 / 360 - 0.5, 0.5, 0.5], 1e-4),
        # opponent: the grey at the centre of the RGB cube maps to the origin
        (cs.opponent_features, (127, 128, 128), [-1 / 255 / S2, -1 / 255 / S6, 0.0], 2e-3),
        # c: each primary reaches one end of the documented ratio ranges (the epsilon, 1/255
        # against O3 = 0.58 for a primary, keeps it 0.7 % inside)
        (cs.c_features, (255, 0, 0), [0.5, None, None], 0.01),  # O1/O3 = +sqrt(1.5)
        (cs.c_features, (0, 255, 0), [-0.5, None, None], 0.01),  # O1/O3 = -sqrt(1.5)
        (cs.c_features, (0, 0, 255), [None, -0.5, None], 0.01),  # O2/O3 = -sqrt(2)
        (cs.c_features, (255, 255, 0), [None, 0.5, 2 / 3 - 0.5], 0.01),  # O2/O3 = 1/sqrt(2)
        # c: black has no chromaticity; the epsilon sends both ratios to 0, which sits in the
        # middle of [-sqrt(1.5), sqrt(1.5)] and at 2/3 of [-sqrt(2), 1/sqrt(2)]
        (cs.c_features, (0, 0, 0), [0.0, 2 / 3 - 0.5, -0.5], 1e-5),
        # so: a flat image has no centre-surround response at all
        (cs.so_features, (200, 30, 90), [0.0] * 12, 1e-5),
    ],
)
def test_known_values(function, rgb, expected, atol: float) -> None:
    out = function(_flat(rgb))[4, 5]
    for value, want in zip(out, expected, strict=True):
        if want is not None:
            assert value == pytest.approx(want, abs=atol)


def test_c_ranges_match_the_documented_bounds() -> None:
    # Exhaustive over a coarse RGB grid: the clipping is only rounding, values stay in ±0.5.
    levels = np.arange(0, 256, 15, dtype=np.uint8)
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1).reshape(1, -1, 3)
    out = cs.c_features(np.ascontiguousarray(grid))
    assert out.min() >= -0.5 - 1e-6 and out.max() <= 0.5 + 1e-6


def test_opponent_is_an_orthonormal_map_of_centred_rgb(stress_image: np.ndarray) -> None:
    rgb = cs.rgb_features(stress_image).reshape(-1, 3).astype(np.float64)
    opp = cs.opponent_features(stress_image).reshape(-1, 3).astype(np.float64)
    matrix, *_ = np.linalg.lstsq(rgb, opp, rcond=None)  # opp = rgb @ matrix, no offset
    np.testing.assert_allclose(matrix.T @ matrix, np.eye(3), atol=1e-5)
    np.testing.assert_allclose(rgb @ matrix, opp, atol=1e-5)
    # so pixel norms (and all distances) are those of the centred RGB
    np.testing.assert_allclose(np.linalg.norm(opp, axis=1), np.linalg.norm(rgb, axis=1), atol=1e-5)


@pytest.mark.parametrize("function", [cs.hue_features, cs.opp_angle_features])
def test_histograms_sum_to_zero_per_pixel(function, stress_image: np.ndarray) -> None:
    out = function(stress_image)
    np.testing.assert_allclose(out.sum(axis=2), 0.0, atol=1e-5)
    assert out.min() >= -1 / 36 - 1e-6


def test_cn_centred_probabilities_sum_to_zero(
    stress_image: np.ndarray, color_names: ColorNameTable
) -> None:
    eleven = color_names(stress_image).astype(np.float64) @ zero_sum_basis(11).T
    np.testing.assert_allclose(eleven.sum(axis=2), 0.0, atol=1e-6)


@pytest.mark.parametrize(
    ("function", "rgb"),
    [
        (cs.hue_features, (90, 90, 90)),  # a grey has no saturation
        (cs.opp_angle_features, (90, 90, 90)),  # a flat image has no derivative...
        (cs.opp_angle_features, (10, 200, 30)),  # ...whatever its colour
    ],
)
def test_histograms_are_uniform_without_weight(function, rgb: tuple[int, int, int]) -> None:
    # Uniform histogram minus 1/36: zero (up to the float32 rounding of eq. 3.1 on a grey).
    np.testing.assert_allclose(function(_flat(rgb)), 0.0, atol=1e-6)


def test_hue_of_red_splits_between_the_bins_around_its_angle() -> None:
    # Red: O1 = 1/sqrt(2), O2 = 1/sqrt(6), H = atan2(O1, O2) = 60 deg, shifted by 180 deg to
    # 240 deg -> position 240/10 - 0.5 = 23.5: half the weight in bin 23, half in bin 24.
    pixel = cs.hue_features(_flat((255, 0, 0)))[4, 5]
    assert set(np.argsort(pixel)[-2:]) == {23, 24}
    assert pixel[23] == pytest.approx(pixel[24], abs=1e-4)
    others = np.delete(pixel, [23, 24])
    np.testing.assert_allclose(others, others[0], atol=1e-7)
    assert pixel[23] > 0.4  # saturation 0.82 >> prior 0.01: nearly all mass in the pair


def test_opp_angle_is_the_same_for_both_edge_directions() -> None:
    # A vertical black|red edge: O1x / O2x = (1/sqrt(2)) / (1/sqrt(6)), angle 60 deg, position
    # 60/5 - 0.5 = 11.5 -> bins 11 and 12. Red|black flips both derivatives: same angle mod pi.
    image = _flat((0, 0, 0), (9, 12))
    image[:, 6:] = (255, 0, 0)
    forward = cs.opp_angle_features(image)[4, 6]
    backward = cs.opp_angle_features(image[:, ::-1].copy())[4, 5]
    assert set(np.argsort(forward)[-2:]) == {11, 12}
    np.testing.assert_allclose(forward, backward, atol=1e-6)


def test_so_on_and_off_respond_to_a_bright_spot() -> None:
    # A white dot on black: O3 (intensity) centre-ON at the dot, OFF in the ring around it.
    image = _flat((0, 0, 0), (21, 21))
    image[10, 10] = 255
    out = cs.so_features(image)
    o3_on, o3_off = 4, 5  # scale 1: O1 ON/OFF, O2 ON/OFF, O3 ON/OFF
    assert out[10, 10, o3_on] > 0.05
    assert out[10, 10, o3_off] == pytest.approx(0.0)
    assert out[10, 13, o3_off] > 0.0  # in the surround
