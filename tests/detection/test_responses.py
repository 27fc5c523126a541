"""Filter responses by matrix products against the direct sum of products."""

from __future__ import annotations

import numpy as np
import pytest

from tracking.detection.dpm import responses
from tracking.detection.dpm.responses import filter_responses


def direct(features: np.ndarray, filt: np.ndarray, y: int, x: int) -> float:
    h, w = filt.shape[:2]
    return float(np.sum(features[y : y + h, x : x + w].astype(np.float64) * filt))


def test_responses_equal_the_direct_sum_for_mixed_filter_sizes():
    rng = np.random.default_rng(0)
    features = rng.random((20, 17, 32), dtype=np.float32)
    filters = [rng.normal(size=s).astype(np.float32) for s in [(6, 6, 32), (15, 5, 32), (6, 6, 32)]]
    out = filter_responses(features, filters)
    # common grid: the smallest height and width of the filters; -inf beyond a filter's own
    assert all(o.shape == (15, 13) for o in out)
    for f, o in zip(filters, out, strict=True):
        h, w = f.shape[:2]
        for y in range(15):
            for x in range(13):
                if y <= 20 - h and x <= 17 - w:
                    assert o[y, x] == pytest.approx(direct(features, f, y, x), rel=1e-5, abs=1e-4)
                else:
                    assert o[y, x] == -np.inf


def test_a_sub_grid_reaching_outside_the_map_is_minus_infinity_there():
    rng = np.random.default_rng(1)
    features = rng.random((12, 10, 32), dtype=np.float32)
    filt = rng.normal(size=(3, 2, 32)).astype(np.float32)
    out = filter_responses(features, [filt], rows=(-2, 5), cols=(6, 12))[0]
    assert out.shape == (7, 6)
    for i, y in enumerate(range(-2, 5)):
        for j, x in enumerate(range(6, 12)):
            if 0 <= y <= 9 and 0 <= x <= 8:
                assert out[i, j] == pytest.approx(direct(features, filt, y, x), rel=1e-5, abs=1e-4)
            else:
                assert out[i, j] == -np.inf


def test_banding_does_not_change_the_result(monkeypatch):
    rng = np.random.default_rng(2)
    features = rng.random((40, 30, 32), dtype=np.float32)
    filters = [rng.normal(size=(6, 6, 32)).astype(np.float32) for _ in range(3)]
    whole = filter_responses(features, filters)
    monkeypatch.setattr(responses, "_BAND_BYTES", 1)  # one output row per band
    banded = filter_responses(features, filters)
    for a, b in zip(whole, banded, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-5)


def test_filters_must_match_the_feature_channels():
    with pytest.raises(ValueError, match=r"\(h, w, 32\)"):
        filter_responses(np.zeros((5, 5, 32), np.float32), [np.zeros((2, 2, 31), np.float32)])
