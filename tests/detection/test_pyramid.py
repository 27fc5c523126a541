"""The pyramid layout of voc-release5 featpyramid.m and its padding."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.detection.dpm.pyramid import (
    level_chains,
    level_features,
    pyramid_levels,
    resize_image,
)
from tracking.features.hog import NUM_FEATURES, fhog, fhog_cells


def test_levels_with_the_extra_octave_follow_featpyramid():
    # 576 x 768 image, sbin 8, interval 10: max_scale = 1 + floor(log(576 / 40) / log(2^0.1))
    levels = pyramid_levels((576, 768, 3), 8, 10, extra_octave=True)
    max_scale = 1 + int(np.floor(np.log(576 / 40) / np.log(2**0.1)))
    assert len(levels) == 10 + 10 + max_scale
    assert [lv.hog_cell for lv in levels[:21]] == [2] * 10 + [4] * 10 + [8]
    # level k - interval has exactly twice the resolution of level k
    for k in range(10, len(levels)):
        assert levels[k - 10].cell == pytest.approx(levels[k].cell / 2)
    assert levels[0].cell == pytest.approx(2.0)
    assert levels[20].cell == pytest.approx(8.0)
    assert [lv.octave for lv in (levels[9], levels[10], levels[19], levels[20], levels[-1])] == [
        0,
        1,
        1,
        2,
        2,
    ]


def test_levels_without_the_extra_octave_start_at_half_sbin():
    levels = pyramid_levels((480, 640), 8, 10, extra_octave=False)
    assert levels[0].hog_cell == 4 and levels[10].hog_cell == 8
    assert levels[10].cell == pytest.approx(8.0)


def test_upscale_divides_every_cell_size():
    plain = pyramid_levels((100, 120), 8, 5, extra_octave=True)
    big = pyramid_levels((100, 120), 8, 5, extra_octave=True, upscale=2.0)
    for a, b in zip(plain, big, strict=False):
        assert b.cell == pytest.approx(a.cell / 2)


def test_padding_marks_the_truncation_channel(pets_frame):
    # featpyramid.m: pad + 1 cells of zeros on each side, truncation channel 1 there only
    levels = pyramid_levels(pets_frame.shape, 8, 10, extra_octave=True)
    level = levels[25]
    padded = level_features(pets_frame, [level], (2, 1))[level.index]
    features = fhog(resize_image(pets_frame, level.factor), 8, truncation_feature=True)
    assert padded.shape == (features.shape[0] + 6, features.shape[1] + 4, 32)
    inside = padded[3:-3, 2:-2]
    np.testing.assert_array_equal(inside, features)
    assert np.all(inside[..., NUM_FEATURES] == 0)
    ring = np.ones(padded.shape[:2], bool)
    ring[3:-3, 2:-2] = False
    assert np.all(padded[ring][:, NUM_FEATURES] == 1)
    assert np.all(padded[ring][:, :NUM_FEATURES] == 0)


def test_level_features_of_a_tiny_image_are_only_padding():
    image = np.zeros((10, 12, 3), np.uint8)
    levels = pyramid_levels(image.shape, 8, 10, extra_octave=True)
    feats = level_features(image, [levels[-1]], (15, 5))
    (only,) = feats.values()
    assert only.shape == (2 * 16, 2 * 6, 32)


@pytest.mark.parametrize(
    ("upscale", "interval", "extra"),
    [(1.0, 10, True), (1.0, 10, False), (1.3, 5, True), (0.7, 7, True), (2.0**0.35, 10, True)],
)
def test_levels_an_octave_apart_form_one_halving_chain(upscale, interval, extra):
    levels = pyramid_levels((576, 768, 3), 8, interval, extra_octave=extra, upscale=upscale)
    chains = level_chains(levels)
    assert len(chains) == interval  # one per level of the first octave
    assert sorted(lv.index for chain in chains for lv in chain) == [lv.index for lv in levels]
    for chain in chains:
        factors = [lv.factor for lv in chain]
        assert factors == sorted(factors, reverse=True)
        ratios = np.log2(np.array(factors[0]) / np.array(factors))
        np.testing.assert_allclose(ratios, np.round(ratios), atol=1e-9)


def test_every_octave_below_is_the_image_above_halved(pets_frame):
    # featpyramid.m: the image of level k + interval is that of level k resized by 0.5, in
    # every chain (an earlier key lookup missed the parent of some chains by a rounding digit)
    levels = pyramid_levels(pets_frame.shape, 8, 10, extra_octave=True)
    got = level_features(pets_frame, levels, (15, 5))
    images: dict[int, np.ndarray] = {}
    for level in levels[20:]:  # the 8-pixel-cell levels; finer ones share these images
        above = images.get(level.index - 10)
        images[level.index] = (
            resize_image(pets_frame, level.factor) if above is None else resize_image(above, 0.5)
        )
        if above is not None:
            assert level.factor == pytest.approx(levels[level.index - 10].factor / 2)
        (expected,) = fhog_cells(images[level.index], [8], truncation_feature=True, margin=(16, 6))
        np.testing.assert_array_equal(got[level.index], expected, err_msg=f"level {level.index}")
    # computed alone, a level is resized from the frame directly (no parent image)
    lower = levels[32]
    alone = level_features(pets_frame, [lower], (15, 5))[lower.index]
    direct = resize_image(pets_frame, lower.factor)
    (padded,) = fhog_cells(direct, [8], truncation_feature=True, margin=(16, 6))
    np.testing.assert_array_equal(alone, padded)
