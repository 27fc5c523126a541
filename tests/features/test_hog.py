"""Felzenszwalb HOG (`tracking.features.hog`) against a scalar port of voc-release5 features.cc.

The reference below is a line-by-line transliteration of ``process()`` in voc-release5
``features/features.cc`` (column-major C indexing rewritten as ``im[y, x, c]``), in double
precision, with the same loops, clamping, tie-breaking and bounds checks.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from tracking.features import hog
from tracking.features.hog import NUM_FEATURES, fhog, fhog_cells, hog_feature_map

UU = (1.0000, 0.9397, 0.7660, 0.500, 0.1736, -0.1736, -0.5000, -0.7660, -0.9397)
VV = (0.0000, 0.3420, 0.6428, 0.8660, 0.9848, 0.9848, 0.8660, 0.6428, 0.3420)

# Feature layout: 0..17 contrast-sensitive, 18..26 insensitive, 27..30 texture, 31 truncation.
SENSITIVE = slice(0, 18)
INSENSITIVE = slice(18, 27)
ORIENTATIONS = slice(0, 27)
TEXTURE = slice(27, 31)


def reference_features(im: np.ndarray, sbin: int) -> np.ndarray:
    """Scalar port of voc-release5 ``features(im, sbin)``: ``(H, W, 3)`` -> ``(h, w, 32)``."""
    dims = im.shape
    blocks = [math.floor(dims[0] / sbin + 0.5), math.floor(dims[1] / sbin + 0.5)]
    hist = np.zeros((blocks[0], blocks[1], 18))
    out = [max(blocks[0] - 2, 0), max(blocks[1] - 2, 0)]
    feat = np.zeros((out[0], out[1], 32))
    visible = [blocks[0] * sbin, blocks[1] * sbin]

    for x in range(1, visible[1] - 1):
        for y in range(1, visible[0] - 1):
            sy, sx = min(y, dims[0] - 2), min(x, dims[1] - 2)
            best_v, dx, dy = -1.0, 0.0, 0.0
            for c in range(3):  # pick channel with strongest gradient (strict >)
                cdy = float(im[sy + 1, sx, c]) - float(im[sy - 1, sx, c])
                cdx = float(im[sy, sx + 1, c]) - float(im[sy, sx - 1, c])
                v = cdx * cdx + cdy * cdy
                if v > best_v:
                    best_v, dx, dy = v, cdx, cdy
            best_dot, best_o = 0.0, 0
            for o in range(9):  # snap to one of 18 orientations
                dot = UU[o] * dx + VV[o] * dy
                if dot > best_dot:
                    best_dot, best_o = dot, o
                elif -dot > best_dot:
                    best_dot, best_o = -dot, o + 9
            xp = (x + 0.5) / sbin - 0.5
            yp = (y + 0.5) / sbin - 0.5
            ixp, iyp = math.floor(xp), math.floor(yp)
            vx0, vy0 = xp - ixp, yp - iyp
            vx1, vy1 = 1.0 - vx0, 1.0 - vy0
            v = math.sqrt(best_v)
            if ixp >= 0 and iyp >= 0:
                hist[iyp, ixp, best_o] += vx1 * vy1 * v
            if ixp + 1 < blocks[1] and iyp >= 0:
                hist[iyp, ixp + 1, best_o] += vx0 * vy1 * v
            if ixp >= 0 and iyp + 1 < blocks[0]:
                hist[iyp + 1, ixp, best_o] += vx1 * vy0 * v
            if ixp + 1 < blocks[1] and iyp + 1 < blocks[0]:
                hist[iyp + 1, ixp + 1, best_o] += vx0 * vy0 * v

    norm = np.zeros((blocks[0], blocks[1]))
    for o in range(9):
        norm += (hist[:, :, o] + hist[:, :, o + 9]) ** 2

    def inv(y0: int, x0: int) -> float:
        s = norm[y0, x0] + norm[y0 + 1, x0] + norm[y0, x0 + 1] + norm[y0 + 1, x0 + 1]
        return 1.0 / math.sqrt(s + 0.0001)

    for x in range(out[1]):
        for y in range(out[0]):
            ns = (inv(y + 1, x + 1), inv(y, x + 1), inv(y + 1, x), inv(y, x))
            src = hist[y + 1, x + 1]
            t = [0.0, 0.0, 0.0, 0.0]
            for o in range(18):
                hs = [min(src[o] * n, 0.2) for n in ns]
                feat[y, x, o] = 0.5 * sum(hs)
                t = [a + b for a, b in zip(t, hs, strict=True)]
            for o in range(9):
                hs = [min((src[o] + src[o + 9]) * n, 0.2) for n in ns]
                feat[y, x, 18 + o] = 0.5 * sum(hs)
            feat[y, x, 27:31] = [0.2357 * a for a in t]
    return feat


def _smooth_image(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Blocky low-frequency image plus mild noise, 0..255: not every cell clips at 0.2."""
    coarse = rng.uniform(0.0, 255.0, size=(shape[0] // 6 + 1, shape[1] // 6 + 1, *shape[2:]))
    up = np.repeat(np.repeat(coarse, 6, axis=0), 6, axis=1)[: shape[0], : shape[1]]
    return np.clip(up + rng.normal(0.0, 4.0, size=shape), 0.0, 255.0)


@pytest.mark.parametrize(
    ("shape", "sbin", "kind"),
    [
        ((40, 48, 3), 4, "noise"),  # whole number of cells, RGB, every cell clips
        ((40, 48, 3), 8, "smooth"),  # DPM cell size on a 5x6-cell image
        ((37, 45, 3), 4, "smooth"),  # round() down: visible region crops the image
        ((44, 52, 3), 8, "noise"),  # 44/8 = 5.5 rounds up: coordinates clamp at H - 2
        ((42, 40), 6, "smooth"),  # grayscale, a cell size that is not a power of two
        ((36, 50), 4, "noise"),  # grayscale noise
        ((40, 48, 3), 4, "uint8"),  # uint8 used as-is (0..255), like voc-release5's doubles
        ((38, 41, 3), 5, "smooth"),  # odd cell: pixels on cell centres; rows clamp, columns crop
        ((20, 18, 3), 2, "noise"),  # small cells
        ((10, 12, 3), 1, "smooth"),  # one-pixel cells: the output is (H - 2, W - 2)
    ],
)
def test_matches_scalar_port_of_features_cc(shape, sbin, kind):
    rng = np.random.default_rng(sum(shape) * 31 + sbin)
    if kind == "noise":
        image = rng.uniform(0.0, 255.0, size=shape).astype(np.float32)
    elif kind == "smooth":
        image = _smooth_image(rng, shape).astype(np.float32)
    else:
        image = rng.integers(0, 256, size=shape, dtype=np.uint8)
    rgb = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)

    expected = reference_features(rgb.astype(np.float64), sbin)
    got = fhog(image, sbin, truncation_feature=True)

    assert got.dtype == np.float32
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5)
    assert 0.0 < got[..., ORIENTATIONS].max() <= 0.4 + 1e-6  # non-trivial values


def test_grayscale_is_three_equal_channels():
    image = _smooth_image(np.random.default_rng(3), (48, 56))
    np.testing.assert_array_equal(fhog(image, 4), fhog(np.dstack([image] * 3), 4))


def test_uint8_and_float_give_the_same_features():
    image = np.random.default_rng(4).integers(0, 256, size=(48, 40, 3), dtype=np.uint8)
    np.testing.assert_array_equal(fhog(image, 8), fhog(image.astype(np.float64), 8))


@pytest.mark.parametrize(
    ("orientation", "sensitive_bin", "insensitive_bin"),
    [
        # Left dark, right bright: dx > 0, dy = 0. The dot with (uu, vv) = (1, 0) is largest and
        # positive, so bin 0 (0°, gradient along +x); insensitive bin 0 -> feature 18.
        ("dark_left", 0, 18),
        # Left bright: dx < 0 -> -dot of o = 0 wins -> bin 9 (180°); same insensitive bin.
        ("dark_right", 9, 18),
        # Top dark, bottom bright: dx = 0, dy > 0. The tables have no 90° direction; 80° (o = 4)
        # and 100° (o = 5) tie at 0.9848 dy and the first one wins: bin 4, insensitive 18 + 4.
        ("dark_top", 4, 22),
        # Top bright: dy < 0 -> -dot of o = 4 wins first -> bin 13 (260°); insensitive 22.
        ("dark_bottom", 13, 22),
    ],
)
def test_step_edge_lands_in_the_gradient_direction_bin(orientation, sensitive_bin, insensitive_bin):
    image = np.zeros((48, 48, 3), dtype=np.float32)
    half = slice(24, None)
    if orientation in ("dark_left", "dark_right"):
        image[:, half] = 200.0
    else:
        image[half, :] = 200.0
    if orientation in ("dark_right", "dark_bottom"):
        image = 200.0 - image

    feat = fhog(image, 8)
    energy = feat.sum(axis=(0, 1))

    assert energy[sensitive_bin] > 0 and energy[insensitive_bin] > 0
    others = np.ones(27, dtype=bool)
    others[[sensitive_bin, insensitive_bin]] = False
    np.testing.assert_array_equal(energy[:27][others], 0.0)
    np.testing.assert_allclose(energy[sensitive_bin], energy[insensitive_bin], rtol=1e-6)


def test_flat_image_gives_zeros():
    feat = fhog(np.full((64, 80, 3), 117.0), 8)
    assert feat.shape == (6, 8, 31)
    np.testing.assert_array_equal(feat, 0.0)


def test_ramp_known_answer():
    # A horizontal ramp has the same gradient everywhere, all in bin 0. Each cell is at least as
    # strong as the others of its blocks, so h * n >= 1/2 and every normalised value clips at
    # 0.2: bins 0 and 18 are 0.5 * 4 * 0.2 = 0.4, each texture feature 0.2357 * 0.2.
    image = np.tile(2.0 * np.arange(64, dtype=np.float32), (48, 1))
    feat = fhog(image, 8)
    expected = np.zeros(31, dtype=np.float32)
    expected[[0, 18]] = 0.4
    expected[TEXTURE] = 0.2357 * 0.2
    np.testing.assert_allclose(feat, np.broadcast_to(expected, feat.shape), atol=1e-6)


def test_faint_ramp_known_answer_below_truncation():
    # A faint ramp (gradient g = 2a per pixel) stays below the 0.2 clip, exposing the
    # normalisation itself. A cell away from the border collects x = sbin^2 g, all in bin 0;
    # each of its blocks has energy 4 x^2, so h * n = x / sqrt(4 x^2 + eps) with eps = 1e-4.
    sbin, a = 8, 7.8125e-6
    image = np.tile(a * np.arange(64.0), (64, 1))
    x = sbin**2 * 2 * a
    h = x / math.sqrt(4 * x * x + 1e-4)  # ~ 0.098
    feat = fhog(image, sbin)[1:-1, 1:-1]  # cells whose blocks avoid the partial border cells
    expected = np.zeros(31)
    expected[[0, 18]] = 0.5 * 4 * h
    expected[TEXTURE] = 0.2357 * h
    np.testing.assert_allclose(feat, np.broadcast_to(expected, feat.shape), rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize(
    ("blue_slope", "expected_bin"),
    [
        (10.0, 0),  # R (along x) and G (along y) equally strong: the first channel, R, wins
        (11.0, 4),  # B (along y) strictly stronger: it wins, bin 4 (80°, first of the tie)
    ],
)
def test_strongest_channel_wins_ties_to_the_first(blue_slope, expected_bin):
    rows, cols = np.mgrid[0:40, 0:40].astype(np.float64)
    image = np.dstack([10.0 * cols, 10.0 * rows, blue_slope * rows])
    energy = fhog(image, 8).sum(axis=(0, 1))[SENSITIVE]
    assert energy[expected_bin] > 0
    np.testing.assert_array_equal(np.delete(energy, expected_bin), 0.0)


def test_truncation_bounds_the_orientation_features():
    # Each normalised value is min(h * n, 0.2); an orientation feature sums four of them with
    # weight 0.5, so it is at most 0.5 * 4 * 0.2 = 0.4 (and a texture feature at most
    # 0.2357 * 18 * 0.2). High-contrast noise pushes many cells to the bound.
    image = np.random.default_rng(5).choice([0.0, 255.0], size=(96, 96, 3))
    feat = fhog(image, 4)
    assert feat[..., ORIENTATIONS].max() <= 0.4 + 1e-6
    assert feat[..., TEXTURE].max() <= 0.2357 * 18 * 0.2 + 1e-6
    assert feat.min() >= 0.0


@pytest.mark.parametrize(
    ("scale", "offset"),
    [
        (4.0, 0.0),  # brighter contrast: the block normalisation divides it out
        (0.25, 0.0),  # dimmer (powers of two keep the orientation decisions bit-identical)
        (1.0, 37.0),  # brightness offset: centred differences do not see it
    ],
)
def test_contrast_and_brightness_invariance(scale, offset):
    image = _smooth_image(np.random.default_rng(6), (64, 72, 3))
    base = fhog(image, 8)
    changed = fhog(scale * image + offset, 8)
    # Only eps = 1e-4 in 1 / sqrt(block energy + eps) breaks exact invariance.
    np.testing.assert_allclose(changed, base, rtol=0, atol=1e-4)


@pytest.mark.parametrize(
    ("shape", "cell", "expected"),
    [
        ((64, 48, 3), 8, (6, 4)),  # whole cells: H / s - 2 by W / s - 2
        ((20, 100, 3), 8, (1, 11)),  # 20 / 8 = 2.5 rounds half up (C round), not to even
        ((19, 100), 8, (0, 11)),  # fewer than 2.5 cells: empty along that axis, no error
        ((2, 2, 3), 1, (0, 0)),  # tinier than the central-difference stencil
        ((0, 0, 3), 8, (0, 0)),  # empty image
    ],
)
def test_fhog_output_shape(shape, cell, expected):
    image = np.random.default_rng(7).uniform(0.0, 255.0, size=shape)
    plain = fhog(image, cell)
    with_truncation = fhog(image, cell, truncation_feature=True)
    assert plain.shape == (*expected, 31)
    assert with_truncation.shape == (*expected, 32)
    np.testing.assert_array_equal(with_truncation[..., 31], 0.0)  # as voc-release5 writes it
    np.testing.assert_array_equal(with_truncation[..., :31], plain)


@pytest.mark.parametrize(
    ("shape", "cell", "expected"),
    [
        ((64, 48, 3), 4, (16, 12)),  # whole cells: H / s by W / s
        ((30, 30), 4, (8, 8)),  # 7.5 cells round half up
        ((5, 5, 3), 4, (1, 1)),  # a single cell
        ((1, 1, 3), 4, (0, 0)),  # less than half a cell
    ],
)
def test_hog_feature_map_shape(shape, cell, expected):
    image = np.random.default_rng(8).uniform(0.0, 255.0, size=shape)
    feat = hog_feature_map(image, cell)
    assert feat.shape == (*expected, 31)
    assert feat.dtype == np.float32


def test_hog_feature_map_covers_the_border_cells():
    # An edge inside the first cell column is cut away by fhog's border ring but appears in
    # the first column of the tracker map, which equals fhog of the edge-padded patch.
    image = np.zeros((32, 32), dtype=np.float32)
    image[:, 2:] = 100.0
    feat = hog_feature_map(image, 4)
    assert feat[:, 0, 0].min() > 0.0
    np.testing.assert_array_equal(feat[:, 2:, :27], 0.0)
    np.testing.assert_array_equal(fhog(np.pad(image, 4, mode="edge"), 4), feat)


@pytest.mark.parametrize(
    ("image", "cell", "message"),
    [
        (np.zeros((32, 32, 4)), 8, r"shape \(H, W\) or \(H, W, 3\), got \(32, 32, 4\)"),  # RGBA
        (np.zeros((32, 32, 3, 1)), 8, r"got \(32, 32, 3, 1\)"),  # 4-D
        (np.zeros(32), 8, r"got \(32,\)"),  # 1-D
        (np.zeros((32, 32), dtype=bool), 8, "integer or floating dtype, got bool"),  # mask
        (np.zeros((32, 32), dtype=complex), 8, "got complex128"),  # complex
        (np.full((32, 32), np.nan), 8, "finite"),  # NaN
        (np.zeros((32, 32)), 0, "positive int, got 0"),  # zero cell size
        (np.zeros((32, 32)), 2.5, "positive int, got 2.5"),  # fractional cell size
        (np.zeros((32, 32)), True, "positive int, got True"),  # bool is not a cell size
    ],
)
def test_bad_input_raises(image, cell, message):
    with pytest.raises(ValueError, match=message):
        fhog(image, cell)
    with pytest.raises(ValueError, match=message):
        hog_feature_map(image, cell)


def _padded(image: np.ndarray, pad: int) -> np.ndarray:
    """``image`` as ``(H, W, 3)`` float64, edge-padded by ``pad`` pixels on every side."""
    rgb = image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)
    return np.pad(rgb.astype(np.float64), ((pad, pad), (pad, pad), (0, 0)), mode="edge")


@pytest.mark.parametrize(
    ("shape", "sbin", "kind"),
    [
        ((28, 20, 3), 4, "uint8"),  # a tracker patch: whole cells, no clamping
        ((30, 30, 3), 4, "uint8"),  # 38 / 4 = 9.5 cells round up: rows and columns clamp
        ((18, 13, 3), 4, "uint8"),  # 4.5 rows of cells round up, 3.25 columns round down
        ((17, 22), 3, "uint8"),  # grayscale 8-bit: one channel, no channel selection
        ((21, 26, 3), 5, "smooth"),  # float patch, odd cell
        ((5, 5, 3), 4, "uint8"),  # a single cell
    ],
)
def test_hog_feature_map_matches_scalar_port(shape, sbin, kind):
    # The kernel pads by clamping image coordinates (no padded copy); the map must be
    # features.cc of the edge-padded patch.
    rng = np.random.default_rng(sum(shape) + sbin)
    if kind == "uint8":
        image = rng.integers(0, 256, size=shape, dtype=np.uint8)
    else:
        image = _smooth_image(rng, shape).astype(np.float32)

    expected = reference_features(_padded(image, sbin), sbin)[..., :31]
    got = hog_feature_map(image, sbin)
    assert got.dtype == np.float32 and got.flags.c_contiguous
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(hog_feature_map(image, sbin), got)  # deterministic


@pytest.mark.parametrize("shape", [(44, 36, 3), (30, 30, 3), (40, 28)])
def test_uint8_path_equals_the_float_path(shape):
    # uint8 images go to the kernel as they are (converted pixel by pixel), float64 ones are
    # converted to float32 first; the float32 decisions and magnitudes are the same, so the
    # features are identical, ties included.
    rng = np.random.default_rng(11)
    image = rng.integers(0, 256, size=shape, dtype=np.uint8)
    if len(shape) == 3:
        image[: shape[0] // 2, :, 1] = image[: shape[0] // 2, :, 0]  # channel ties
    as_float = image.astype(np.float64)
    np.testing.assert_array_equal(hog_feature_map(image, 4), hog_feature_map(as_float, 4))
    np.testing.assert_array_equal(fhog(image, 4), fhog(as_float, 4))


def _double_precision_orientations(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """features.cc's "if (dot > best) ... else if (-dot > best)" chain in float64."""
    best = np.zeros(dx.shape)
    orient = np.zeros(dx.shape, dtype=np.int64)
    for o in range(9):
        dot = UU[o] * dx + VV[o] * dy
        positive = dot > best
        best = np.where(positive, dot, best)
        orient = np.where(positive, o, orient)
        negative = ~positive & (-dot > best)
        best = np.where(negative, -dot, best)
        orient = np.where(negative, o + 9, orient)
    return orient


def test_single_precision_orientations_are_exact_for_integer_gradients():
    # The module docstring's claim: float32 orientation decisions agree with double precision
    # for every integer gradient up to +-510 (the kernel's own orientation step).
    span = np.arange(-510, 511)
    dx, dy = (a.ravel() for a in np.meshgrid(span, span, indexing="ij"))
    expected = _double_precision_orientations(dx.astype(np.float64), dy.astype(np.float64))
    gx, gy = dx.astype(np.float32), dy.astype(np.float32)
    got = np.empty(gx.size, dtype=np.int32)
    hog._orientations(gx, gy, got)
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("grayscale", [False, True])
def test_strided_views_give_the_same_features(grayscale):
    # The kernel reads any strides (a BGR -> RGB view, a crop) without a contiguous copy.
    rng = np.random.default_rng(12)
    base = rng.integers(0, 256, size=(50, 60, 3), dtype=np.uint8)
    view = base[3:45, 5:, 1] if grayscale else base[3:45, 5:, ::-1]
    copy = np.ascontiguousarray(view)
    assert not view.flags.c_contiguous
    np.testing.assert_array_equal(fhog(view, 4), fhog(copy, 4))
    np.testing.assert_array_equal(hog_feature_map(view, 4), hog_feature_map(copy, 4))
    floats = view.astype(np.float32)[::-1]
    np.testing.assert_array_equal(fhog(floats, 4), fhog(np.ascontiguousarray(floats), 4))


def _image(kind: str, shape: tuple[int, int], seed: int) -> np.ndarray:
    """A random ``(H, W, 3)`` or ``(H, W)`` image: uint8 or float32 in 0..255, or a BGR view."""
    rng = np.random.default_rng(seed)
    if kind == "uint8":
        return rng.integers(0, 256, size=(*shape, 3), dtype=np.uint8)
    if kind == "float32":
        return _smooth_image(rng, (*shape, 3)).astype(np.float32)
    if kind == "gray_uint8":
        return rng.integers(0, 256, size=shape, dtype=np.uint8)
    if kind == "gray_float32":
        return rng.uniform(0.0, 255.0, size=shape).astype(np.float32)
    return rng.integers(0, 256, size=(*shape, 3), dtype=np.uint8)[:, ::-1, ::-1]  # "view"


def _assert_same_as_fhog(image: np.ndarray, sizes, truncation_feature: bool) -> None:
    """``fhog_cells`` is ``[fhog(image, s) for s in sizes]``, bit for bit."""
    got = fhog_cells(image, sizes, truncation_feature=truncation_feature)
    assert isinstance(got, list) and len(got) == len(sizes)
    for size, feat in zip(sizes, got, strict=True):
        expected = fhog(image, size, truncation_feature=truncation_feature)
        assert feat.dtype == np.float32 and feat.flags.c_contiguous
        assert feat.shape == expected.shape, size
        np.testing.assert_array_equal(feat, expected, err_msg=f"cell size {size}")


@pytest.mark.parametrize("shape", [(37, 53), (64, 48), (101, 77), (44, 52)])
@pytest.mark.parametrize("kind", ["uint8", "float32", "gray_uint8", "gray_float32", "view"])
@pytest.mark.parametrize(
    "sizes",
    [
        (2, 4, 8),  # the DPM pyramid's cell sizes
        (4, 8),
        (8,),  # one size
        (8, 4, 2),  # any order
        (4, 4),  # repeated
        (1, 3, 5, 6, 7, 9),  # odd sizes: each crops or clamps the image differently
        (8, 24, 48),  # too large for the image along one or both axes: empty maps
    ],
)
def test_fhog_cells_equals_fhog_per_size(shape, kind, sizes):
    # The pixel pass is shared; each size visits its own rows and columns (cropped, or the
    # last interior one repeated), which must come out as fhog computes them alone.
    image = _image(kind, shape, seed=sum(shape) + len(sizes))
    _assert_same_as_fhog(image, sizes, truncation_feature=True)
    _assert_same_as_fhog(image, sizes, truncation_feature=False)


@pytest.fixture(scope="module")
def pets_frame(shared_data: Path) -> np.ndarray:
    """Frame 10 of PETS09-S2L1 (768x576), RGB as a view of OpenCV's BGR."""
    path = shared_data / "mot" / "PETS09-S2L1" / "img1" / "000010.jpg"
    return cv2.imread(str(path))[..., ::-1]


@pytest.mark.parametrize("sizes", [(2, 4, 8), (4, 8), (8,), (4, 4)])
@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_fhog_cells_on_a_pets_frame(pets_frame, sizes, dtype):
    # The DPM pyramid's use: the same (resized, float32) image at cells of 2, 4 and 8.
    _assert_same_as_fhog(pets_frame.astype(dtype), sizes, truncation_feature=True)


def test_fhog_cells_on_resized_pets_frames(pets_frame):
    # Pyramid levels: sizes where some cell sizes leave an empty map.
    for width, height in ((333, 251), (40, 30), (21, 17)):
        scaled = cv2.resize(pets_frame.astype(np.float32), (width, height), cv2.INTER_AREA)
        _assert_same_as_fhog(scaled, (2, 4, 8), truncation_feature=True)


def test_fhog_cells_repeated_sizes_are_separate_arrays():
    image = _image("uint8", (40, 48), seed=1)
    first, second = fhog_cells(image, [4, 4])
    np.testing.assert_array_equal(first, second)
    assert not np.shares_memory(first, second)


@pytest.mark.parametrize(
    ("shape", "sizes", "expected"),
    [
        ((5, 5, 3), (4, 8), [(0, 0), (0, 0)]),  # smaller than 2.5 cells of any size
        ((0, 0, 3), (2, 8), [(0, 0), (0, 0)]),  # empty image
        ((20, 100), (8, 16), [(1, 11), (0, 4)]),  # 20 / 16 rounds to 1 cell: that map empty
        ((2, 2, 3), (1,), [(0, 0)]),  # tinier than the central-difference stencil
    ],
)
def test_fhog_cells_output_shapes(shape, sizes, expected):
    image = np.random.default_rng(7).uniform(0.0, 255.0, size=shape)
    got = fhog_cells(image, sizes, truncation_feature=True)
    assert [feat.shape for feat in got] == [(*cells, 32) for cells in expected]
    for feat in got:
        np.testing.assert_array_equal(feat[..., 31], 0.0)


def test_fhog_cells_with_no_sizes_is_empty():
    assert fhog_cells(np.zeros((32, 32, 3)), []) == []
    assert fhog_cells(np.zeros((32, 32, 3)), ()) == []


def test_fhog_cells_accepts_any_sequence_of_ints():
    image = _image("uint8", (40, 48), seed=2)
    expected = fhog_cells(image, [4, 8])
    for sizes in ((4, 8), np.array([4, 8]), range(4, 9, 4), [np.int32(4), np.int64(8)]):
        for feat, reference in zip(fhog_cells(image, sizes), expected, strict=True):
            np.testing.assert_array_equal(feat, reference)


def _in_margin(feat: np.ndarray, rows: int, cols: int, truncation_feature: bool) -> np.ndarray:
    """``feat`` inside a margin of zeros, its truncation channel 1 there (featpyramid.m)."""
    out = np.pad(feat, ((rows, rows), (cols, cols), (0, 0)))
    if truncation_feature:
        ring = np.ones(out.shape[:2], dtype=bool)
        ring[rows : rows + feat.shape[0], cols : cols + feat.shape[1]] = False
        out[ring, NUM_FEATURES] = 1.0
    return out


@pytest.mark.parametrize("margin", [(16, 6), (0, 3), (2, 0), [1, 1], (np.int64(4), 5)])
@pytest.mark.parametrize("truncation_feature", [True, False])
def test_fhog_cells_margin_is_zero_padding_marked_as_outside(margin, truncation_feature):
    # The maps are written in place inside the margin: the same values as padding afterwards.
    rows, cols = (int(m) for m in margin)
    image = _image("uint8", (61, 45), seed=3)
    sizes = (2, 4, 8, 24)  # 24: empty map, margin only
    got = fhog_cells(image, sizes, truncation_feature=truncation_feature, margin=margin)
    for size, feat in zip(sizes, got, strict=True):
        alone = fhog(image, size, truncation_feature=truncation_feature)
        expected = _in_margin(alone, rows, cols, truncation_feature)
        assert feat.dtype == np.float32 and feat.flags.c_contiguous
        np.testing.assert_array_equal(feat, expected, err_msg=f"cell size {size}")


def test_fhog_cells_margin_on_a_pets_frame(pets_frame):
    image = pets_frame.astype(np.float32)
    got = fhog_cells(image, (2, 4, 8), truncation_feature=True, margin=(16, 6))
    for size, feat in zip((2, 4, 8), got, strict=True):
        expected = _in_margin(fhog(image, size, truncation_feature=True), 16, 6, True)
        np.testing.assert_array_equal(feat, expected, err_msg=f"cell size {size}")


@pytest.mark.parametrize("margin", [(-1, 2), (1,), 3, (1.5, 2), (True, 1), None, (1, 2, 3)])
def test_fhog_cells_bad_margin_raises(margin):
    with pytest.raises(ValueError, match="margin must be two non-negative ints"):
        fhog_cells(np.zeros((32, 32, 3)), (4, 8), margin=margin)


@pytest.mark.parametrize(
    ("sizes", "message"),
    [
        ((4, 0), "positive int, got 0"),  # zero cell size
        ([8, 2.5], "positive int, got 2.5"),  # fractional
        ((True,), "positive int, got True"),  # bool
        (4, "sequence of positive ints, got 4"),  # one int, not a sequence
        ("48", "sequence of positive ints, got '48'"),  # a string is not a sequence of ints
        (None, "sequence of positive ints, got None"),
    ],
)
def test_fhog_cells_bad_cell_sizes_raise(sizes, message):
    with pytest.raises(ValueError, match=message):
        fhog_cells(np.zeros((32, 32, 3)), sizes)


@pytest.mark.parametrize(
    ("image", "message"),
    [
        (np.zeros((32, 32, 4)), r"shape \(H, W\) or \(H, W, 3\)"),  # RGBA
        (np.full((32, 32), np.inf), "finite"),
        (np.zeros((32, 32), dtype=bool), "integer or floating dtype"),
    ],
)
def test_fhog_cells_bad_image_raises(image, message):
    with pytest.raises(ValueError, match=message):
        fhog_cells(image, (4, 8))
    with pytest.raises(ValueError, match=message):
        fhog_cells(image, [])  # validated even with no sizes, as fhog validates it
