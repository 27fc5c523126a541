"""Distance transforms against brute force: values and argmax placements."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.detection.dpm.distance_transform import (
    bounded_distance_transform,
    distance_transform,
    distance_transform_1d,
)


def brute_force(values: np.ndarray, weights: np.ndarray, window: int | None = None):
    """``max_{y', x'} f[y', x'] - cost(y - y', x - x')`` by enumeration, first maximum wins
    in row-major placement order (which the separable passes reproduce for distinct values)."""
    count, height, width = values.shape
    out = np.full(values.shape, -np.inf)
    ix = np.zeros(values.shape, dtype=int)
    iy = np.zeros(values.shape, dtype=int)
    py, px = np.mgrid[0:height, 0:width]
    for k in range(count):
        ax, bx, ay, by = weights[k]
        for y in range(height):
            for x in range(width):
                dy, dx = y - py, x - px
                cand = values[k] - (ax * dx**2 + bx * dx + ay * dy**2 + by * dy)
                if window is not None:
                    cand = np.where((abs(dx) <= window) & (abs(dy) <= window), cand, -np.inf)
                best = int(np.argmax(cand))
                out[k, y, x] = cand.flat[best]
                iy[k, y, x], ix[k, y, x] = divmod(best, width)
    return out, ix, iy


def random_case(seed: int, shape=(3, 9, 11), holes: bool = True):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=shape)
    if holes:  # -inf where a filter does not fit, as on the border of a response map
        values[0, 2, 3] = -np.inf
        values[1, :, :4] = -np.inf
    count = shape[0]
    weights = np.column_stack(
        [
            rng.uniform(0.01, 1.0, count),
            rng.normal(size=count),
            rng.uniform(0.01, 1.0, count),
            rng.normal(size=count),
        ]
    )
    return values, weights


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_unbounded_transform_equals_brute_force(seed):
    values, weights = random_case(seed)
    out, ix, iy = distance_transform(values, weights)
    ref, rix, riy = brute_force(values, weights)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ix, rix)
    np.testing.assert_array_equal(iy, riy)


@pytest.mark.parametrize("window", [0, 1, 2, 4])
def test_bounded_transform_equals_brute_force(window):
    values, weights = random_case(window + 10)
    out, ix, iy = bounded_distance_transform(values, weights, window)
    ref, rix, riy = brute_force(values, weights, window)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
    finite = np.isfinite(ref)  # no placement at all where the window holds only -inf
    np.testing.assert_array_equal(ix[finite], rix[finite])
    np.testing.assert_array_equal(iy[finite], riy[finite])


def test_bounded_transform_on_a_sub_grid_of_outputs():
    # rows 1, 3, 5, 7 and columns 0, 3, 6, 9: what a root grid reads from its parts' level
    values, weights = random_case(7)
    out, ix, iy = bounded_distance_transform(values, weights, 2, rows=(1, 2, 4), cols=(0, 3, 4))
    ref, rix, riy = brute_force(values, weights, 2)
    sub = (slice(None), slice(1, 9, 2), slice(0, 12, 3))
    np.testing.assert_allclose(out, ref[sub], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ix, rix[sub])
    np.testing.assert_array_equal(iy, riy[sub])


def test_bounded_transform_outputs_beyond_the_input_reach_in():
    # outputs outside the value grid still see placements within the window
    values, weights = random_case(3, shape=(1, 6, 6), holes=False)
    out, _, iy = bounded_distance_transform(values, weights, 3, rows=(-2, 1, 10), cols=(0, 1, 6))
    padded = np.full((1, 10, 6), -np.inf)
    padded[:, 2:8] = values
    ref, _, riy = brute_force(padded, weights, 3)
    np.testing.assert_allclose(out, ref, atol=1e-12)
    finite = np.isfinite(ref)
    np.testing.assert_array_equal(iy[finite], riy[finite] - 2)


def test_float32_input_stays_float32_and_agrees():
    values, weights = random_case(5, holes=False)
    out32, _, _ = bounded_distance_transform(values.astype(np.float32), weights, 4)
    out64, _, _ = bounded_distance_transform(values, weights, 4)
    assert out32.dtype == np.float32
    np.testing.assert_allclose(out32, out64, atol=1e-5)


def test_one_dimensional_lines_with_their_own_weights():
    rng = np.random.default_rng(4)
    f = rng.normal(size=(5, 17))
    a = rng.uniform(0.05, 2.0, 5)
    b = rng.normal(size=5)
    out, arg = distance_transform_1d(f, a, b)
    p = np.arange(17)
    t = p[:, None] - p[None, :]  # output p, placement q
    cand = f[:, None, :] - (a[:, None, None] * t**2 + b[:, None, None] * t)
    np.testing.assert_allclose(out, cand.max(axis=2), atol=1e-12)
    np.testing.assert_array_equal(arg, cand.argmax(axis=2))


def test_all_minus_infinity_line_stays_minus_infinity():
    values = np.full((1, 3, 4), -np.inf)
    out, _, _ = distance_transform(values, [0.1, 0.0, 0.1, 0.0])
    assert np.all(np.isneginf(out))


@pytest.mark.parametrize(
    "weights",
    [
        [0.0, 0.0, 1.0, 0.0],  # a_x = 0: no lower envelope of parabolas
        [1.0, 0.0, -1.0, 0.0],  # negative curvature
        [1.0, np.nan, 1.0, 0.0],  # not finite
        [1.0, 0.0, 1.0],  # wrong length
    ],
)
def test_bad_deformation_weights_are_rejected(weights):
    with pytest.raises(ValueError, match="deformation"):
        distance_transform(np.zeros((1, 3, 3)), weights)
