"""Star-model scores against a hand computation: filter responses minus deformation costs."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tracking.detection.dpm.model import DpmComponent, DpmModel, FilterSymbol
from tracking.detection.dpm.pyramid import PyramidLevel, level_features, pyramid_levels
from tracking.detection.dpm.scoring import score_level

PAD = (3, 2)  # (pad_y, pad_x) of the synthetic maps


def response(features: np.ndarray, weights: np.ndarray, y: int, x: int) -> float:
    """Filter response by the definition; -inf where the filter does not fit."""
    h, w = weights.shape[:2]
    if y < 0 or x < 0 or y + h > features.shape[0] or x + w > features.shape[1]:
        return -np.inf
    return float(np.sum(features[y : y + h, x : x + w].astype(np.float64) * weights))


def symbol_score(features, symbol, anchor_y, anchor_x, window):
    """max over placements (py, px) of response - cost(anchor - placement), by enumeration.

    As voc-release5, a symbol whose anchor lies outside its response map scores -inf.
    """
    if response(features, symbol.weights, anchor_y, anchor_x) == -np.inf:
        return -np.inf
    if symbol.deformation is None:  # a filter without a deformation rule stays at its anchor
        return response(features, symbol.weights, anchor_y, anchor_x)
    ax, bx, ay, by = symbol.deformation
    best = -np.inf
    reach = window if window is not None else max(features.shape[:2])
    for py, px in itertools.product(
        range(anchor_y - reach, anchor_y + reach + 1), range(anchor_x - reach, anchor_x + reach + 1)
    ):
        r = response(features, symbol.weights, py, px)
        dy, dx = anchor_y - py, anchor_x - px
        best = max(best, r - (ax * dx * dx + bx * dx + ay * dy * dy + by * dy))
    return best


def hand_score(model, features, level, y, x, window):
    """Eq. 2 of Felzenszwalb et al. (2010) at root position (y, x) of ``level``, per component."""
    out = []
    for comp in model.components:
        total = comp.bias + comp.location[level.octave]
        for symbol in comp.symbols:
            ax, ay, ds = symbol.anchor
            step = 2**ds
            table = level.index - level.interval * ds
            anchor_y = step * y + ay - (step - 1) * PAD[0]  # voc-release5 virtual padding
            anchor_x = step * x + ax - (step - 1) * PAD[1]
            octave = min(table // level.interval, 2)
            total += symbol_score(features[table], symbol, anchor_y, anchor_x, window)
            total += symbol.bias + symbol.location[octave]
        out.append(total)
    return out


def synthetic_model(rng) -> DpmModel:
    def symbol(index, size, anchor, deformation, bias=0.0):
        return FilterSymbol(
            filter_index=index,
            weights=rng.normal(size=(*size, 32)).astype(np.float32),
            anchor=anchor,
            deformation=None if deformation is None else np.array(deformation, float),
            bias=bias,
            location=rng.normal(size=3) * 0.1,
        )

    comps = []
    for c in range(2):
        # component 0's root has voc-release5's pinning deformation rule, component 1's none
        root = symbol(3 * c, (3, 2), (0, 0, 0), [1000, 0, 1000, 0] if c == 0 else None)
        parts = (
            symbol(3 * c + 1, (2, 2), (0, 1, 1), [0.05, 0.1, 0.08, -0.05], 0.3),
            symbol(3 * c + 2, (2, 3), (1, 3, 1), [0.2, -0.3, 0.04, 0.2], -0.2),
        )
        comps.append(
            DpmComponent(
                index=c,
                root=root,
                parts=parts,
                bias=float(rng.normal()),
                location=rng.normal(size=3) * 0.1,
                window=(3, 2),
                shift=(0, 0),
                mirrored=bool(c),
                bbox_regression=None,
            )
        )
    return DpmModel("synthetic", tuple(comps), sbin=8, interval=2, threshold=0.0, max_size=(3, 2),
                    extra_octave=False)  # fmt: skip


@pytest.mark.parametrize("window", [None, 2, 4])
def test_synthetic_scores_equal_hand_computation(window):
    rng = np.random.default_rng(0)
    model = synthetic_model(rng)
    level = PyramidLevel(index=2, factor=0.5, hog_cell=8, interval=2)  # parts on level 0
    features = {
        2: rng.random((9, 8, 32), dtype=np.float32),
        0: rng.random((18, 16, 32), dtype=np.float32),
    }
    scored = score_level(model, features, level, PAD, window=window)
    ny, nx = scored.scores.shape
    assert (ny, nx) == (9 - 3 + 1, 8 - 2 + 1)
    for y, x in itertools.product(range(ny), range(nx)):
        expected = hand_score(model, features, level, y, x, window)
        np.testing.assert_allclose(scored.component_scores[:, y, x], expected, rtol=1e-5, atol=1e-4)
        assert scored.scores[y, x] == pytest.approx(max(expected), rel=1e-5, abs=1e-4)


def test_synthetic_placements_achieve_the_score():
    # the argmax placements, put back into the formula, give the reported score
    rng = np.random.default_rng(1)
    model = synthetic_model(rng)
    level = PyramidLevel(index=2, factor=0.5, hog_cell=8, interval=2)
    features = {
        2: rng.random((9, 8, 32), dtype=np.float32),
        0: rng.random((18, 16, 32), dtype=np.float32),
    }
    scored = score_level(model, features, level, PAD, window=4)
    y, x = 3, 2
    c = int(scored.component[y, x])
    comp = model.components[c]
    total = comp.bias + comp.location[level.octave]
    for j, symbol in enumerate(comp.symbols):
        ax, ay, ds = symbol.anchor
        step = 2**ds
        table = level.index - level.interval * ds
        px, py = scored.placements[c, j, y, x]
        dy = step * y + ay - (step - 1) * PAD[0] - py
        dx = step * x + ax - (step - 1) * PAD[1] - px
        a_x, b_x, a_y, b_y = symbol.deformation if symbol.deformation is not None else (0,) * 4
        assert symbol.deformation is not None or (dx, dy) == (0, 0)
        total += response(features[table], symbol.weights, py, px)
        total -= a_x * dx * dx + b_x * dx + a_y * dy * dy + b_y * dy
        total += symbol.bias + symbol.location[min(table // level.interval, 2)]
    assert scored.scores[y, x] == pytest.approx(total, rel=1e-5, abs=1e-4)


@pytest.mark.slow
def test_inria_score_at_a_person_equals_brute_force(inria_model, pets_frame):
    # A crop around the person at (258, 219, 33 x 89) of PETS09-S2L1 frame 1
    crop = pets_frame[150:330, 200:330]
    levels = pyramid_levels(crop.shape, 8, 10, extra_octave=True)
    root = next(lv for lv in levels if lv.index >= 10 and 80 <= 15 * lv.cell <= 95)
    part = levels[root.index - 10]
    features = level_features(crop, [root, part], inria_model.max_size)
    scored = score_level(inria_model, features, root, inria_model.max_size, window=4)
    y, x = np.unravel_index(np.argmax(scored.scores), scored.scores.shape)
    expected = hand_score_with_pad(inria_model, features, root, int(y), int(x), 4)
    np.testing.assert_allclose(scored.component_scores[:, y, x], expected, rtol=1e-5, atol=1e-4)
    assert scored.scores[y, x] > 0  # a person: above the model's threshold


def hand_score_with_pad(model, features, level, y, x, window):
    global PAD
    saved, PAD = PAD, model.max_size
    try:
        return hand_score(model, features, level, y, x, window)
    finally:
        PAD = saved
