"""STRCF (tracking/correlation/regularized.py) and what came with it: the ADMM steps against
brute-force solutions, the helpers (penalty window, grid zoom, block projection, APCE), the
configuration's checks, and the ``strcf_hog_cn`` preset on synthetic occlusions and on OTB Deer."""

import dataclasses

import numpy as np
import pytest
from scipy import fft, ndimage

from tracking.correlation import PRESETS, CorrelationConfig, CorrelationTracker, ScaleConfig
from tracking.correlation.config import AdmmSchedule
from tracking.correlation.patches import zoom_about_centre
from tracking.correlation.projection import block_projection
from tracking.correlation.regularized import (
    PENALTY_OFF_TARGET,
    PENALTY_ON_TARGET,
    TemporalRegularizedFilter,
    solve_auxiliary_step,
    solve_filter_step,
    target_penalty_window,
)
from tracking.correlation.signals import (
    average_peak_to_correlation_energy,
    gaussian_label,
    hann_window,
)
from tracking.datasets.otb import load_otb_sequence, read_frame
from tracking.evaluation.metrics import center_location_error, iou
from tracking.types import Box

SHAPE = (5, 6)  # M, N: tiny, so that the correlation operator fits in an explicit matrix
CELLS = SHAPE[0] * SHAPE[1]  # T
DIMS = 2


def half_spectrum(rng, shape):
    """The half-plane spectrum (rfft2 over the first two axes) of a random real array."""
    return fft.rfft2(rng.standard_normal(shape), axes=(0, 1))


def correlation_matrix(x):
    """The operator ``f -> r`` with ``r(tau) = sum_d sum_t f_d(t) x_d(t + tau)`` (circular), as a
    ``(M N, D M N)`` matrix acting on :func:`as_vector` of ``f``."""
    rows, cols, _ = x.shape
    return np.stack(
        [
            np.roll(x, (-m, -n), axis=(0, 1)).transpose(2, 0, 1).ravel()
            for m in range(rows)
            for n in range(cols)
        ]
    )


def as_vector(f):
    """``(M, N, D)`` flattened channel by channel: the columns of :func:`correlation_matrix`."""
    return f.transpose(2, 0, 1).ravel()


def strcf_minimiser(x, y, window, mu, previous):
    """argmin_f 1/2 ||sum_d x_d * f_d - y||^2 + T/2 sum_d ||w . f_d||^2 + T mu/2 ||f - f'||^2
    (the module docstring's objective) by its normal equations, as a vector."""
    a = correlation_matrix(x)
    cells = x.shape[0] * x.shape[1]
    penalty = np.diag(np.tile(window.ravel() ** 2, x.shape[2]))
    lhs = a.T @ a + cells * penalty + cells * mu * np.eye(a.shape[1])
    return np.linalg.solve(lhs, a.T @ y.ravel() + cells * mu * as_vector(previous))


def admm(x, y, window, mu, previous, gammas):
    """STRCF's ADMM from the module's two steps, iterated as TemporalRegularizedFilter.train
    iterates them; the spatial filter ``(M, N, D)``."""
    shape = x.shape[:2]
    cells = shape[0] * shape[1]
    x_hat = fft.rfft2(x, axes=(0, 1))
    y_hat = fft.rfft2(y)
    previous_hat = fft.rfft2(previous, axes=(0, 1))
    f_hat = g_hat = h_hat = np.zeros_like(x_hat)
    for i, gamma in enumerate(gammas):
        f_hat = solve_filter_step(x_hat, y_hat, g_hat, h_hat, previous_hat, gamma, mu, cells)
        if i == len(gammas) - 1:
            break
        weighted = fft.irfft2(gamma * f_hat + h_hat, s=shape, axes=(0, 1))
        g_hat = fft.rfft2(solve_auxiliary_step(weighted, window, gamma), axes=(0, 1))
        h_hat = h_hat + gamma * (f_hat - g_hat)
    return fft.irfft2(f_hat, s=shape, axes=(0, 1))


# -- the ADMM steps --------------------------------------------------------------------------


def test_filter_step_solves_the_per_frequency_system():
    rng = np.random.default_rng(0)
    shape = (*SHAPE, DIMS)
    x, g, h, previous = (half_spectrum(rng, shape) for _ in range(4))
    y = half_spectrum(rng, SHAPE)
    gamma, mu = 0.8, 0.7
    f = solve_filter_step(x, y, g, h, previous, gamma, mu, CELLS)
    assert f.shape == x.shape
    for i in range(x.shape[0]):
        for j in range(x.shape[1]):
            xj = x[i, j]
            lhs = np.outer(xj, np.conj(xj)) + CELLS * (gamma + mu) * np.eye(DIMS)
            rhs = xj * np.conj(y[i, j]) + CELLS * (gamma * g[i, j] - h[i, j] + mu * previous[i, j])
            np.testing.assert_allclose(f[i, j], np.linalg.solve(lhs, rhs), rtol=1e-10, atol=1e-12)


def test_the_explicit_correlation_matrix_is_the_fft_response():
    # what the brute force below minimises is what the filter's response computes
    rng = np.random.default_rng(1)
    x = rng.standard_normal((*SHAPE, DIMS))
    f = rng.standard_normal((*SHAPE, DIMS))
    product = np.sum(np.conj(fft.rfft2(f, axes=(0, 1))) * fft.rfft2(x, axes=(0, 1)), axis=2)
    response = fft.irfft2(product, s=SHAPE)
    np.testing.assert_allclose(correlation_matrix(x) @ as_vector(f), response.ravel(), atol=1e-12)


@pytest.mark.parametrize("mu", [0.0, 0.7])  # the first frame (no temporal term) and the others
def test_admm_converges_to_the_minimiser_of_the_strcf_objective(mu):
    rng = np.random.default_rng(2)
    x = rng.standard_normal((*SHAPE, DIMS))
    y = rng.standard_normal(SHAPE)
    previous = rng.standard_normal((*SHAPE, DIMS))
    # Not binary, so that the penalty's value counts everywhere, not only on or off the box
    window = np.full(SHAPE, 3.0)
    window[1:4, 2:5] = 0.1
    expected = strcf_minimiser(x, y, window, mu, previous)
    gammas = AdmmSchedule(iterations=3000, initial=1.0, maximum=1.0, step=1.0).penalties()
    found = as_vector(admm(x, y, window, mu, previous, gammas))
    np.testing.assert_allclose(found, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    # and two iterations (the preset's schedule) are not there yet: the test can tell
    rough = as_vector(admm(x, y, window, mu, previous, AdmmSchedule().penalties()))
    assert np.abs(rough - expected).max() > 1e-3


def test_the_filter_class_minimises_the_objective_frame_after_frame():
    """TemporalRegularizedFilter itself (its label, Hann window and binary penalty): the first
    frame without the temporal term, the second tied to the first frame's filter."""
    target, sigma, mu = (2.0, 3.0), 0.25, 0.7
    # gamma 0.3: with the binary window's 1e5 ADMM needs 10000 iterations at gamma 1 here
    schedule = AdmmSchedule(iterations=3000, initial=0.3, maximum=0.3, step=1.0)
    learner = TemporalRegularizedFilter(SHAPE, target, sigma, mu, schedule)
    rng = np.random.default_rng(3)
    first, second = rng.standard_normal((2, *SHAPE, DIMS))
    label = np.fft.ifftshift(gaussian_label(SHAPE, target, sigma)).astype(np.float64)
    window = target_penalty_window(SHAPE, target)
    hann = hann_window(SHAPE)[:, :, None]

    def spatial_filter():
        return as_vector(fft.irfft2(learner.filter_spectrum, s=SHAPE, axes=(0, 1)))

    learner.initialize(first)
    expected = strcf_minimiser(first * hann, label, window, 0.0, np.zeros((*SHAPE, DIMS)))
    found_first = spatial_filter()
    # up to the complex64 the learner keeps its label and filter in (measured: 1e-5 of the max)
    np.testing.assert_allclose(found_first, expected, atol=1e-4 * np.abs(expected).max())

    learner.update(second)
    previous = found_first.reshape(DIMS, *SHAPE).transpose(1, 2, 0)
    expected = strcf_minimiser(second * hann, label, window, mu, previous)
    np.testing.assert_allclose(spatial_filter(), expected, atol=1e-4 * np.abs(expected).max())


# -- the learner -----------------------------------------------------------------------------


def test_the_penalty_window_is_small_on_the_target_and_huge_elsewhere():
    window = target_penalty_window((9, 10), (3.9, 4.7))  # floored to 3 x 4 cells
    on = np.zeros((9, 10), bool)
    on[3:6, 3:7] = True  # rows 9 // 2 - 3 // 2 .., columns 10 // 2 - 4 // 2 ..
    assert on[9 // 2, 10 // 2]
    np.testing.assert_array_equal(window[on], PENALTY_ON_TARGET)
    np.testing.assert_array_equal(window[~on], PENALTY_OFF_TARGET)
    assert PENALTY_ON_TARGET < 1e-2 and PENALTY_OFF_TARGET > 1e4

    tiny = target_penalty_window((9, 10), (0.3, 0.6))  # at least one cell: the centre
    assert np.flatnonzero(tiny.ravel() == PENALTY_ON_TARGET).tolist() == [4 * 10 + 5]
    huge = target_penalty_window((5, 6), (40.0, 7.5))  # no larger than the grid
    np.testing.assert_array_equal(huge, PENALTY_ON_TARGET)


def smooth_features(rng, shape=(20, 24), dims=3):
    return ndimage.gaussian_filter(rng.standard_normal((*shape, dims)), (1.0, 1.0, 0.0))


def preset_like_filter(shape=(20, 24)):
    """A learner with the preset's label, temporal regularisation and ADMM schedule."""
    config = PRESETS["strcf_hog_cn"]
    return TemporalRegularizedFilter(
        shape, (5.0, 6.0), config.label_sigma, config.temporal_regularization, config.admm
    )


def test_the_response_to_the_training_sample_peaks_at_the_centre():
    rng = np.random.default_rng(4)
    x = smooth_features(rng)
    learner = preset_like_filter()
    learner.initialize(x)
    response = learner.response(x)
    assert response.shape == (20, 24)
    assert np.unravel_index(np.argmax(response), response.shape) == (10, 12)
    # the target moved by (2, -3) cells: so does the peak (the tracker reads motion off it)
    moved = learner.response(np.roll(x, (2, -3), axis=(0, 1)))
    assert np.unravel_index(np.argmax(moved), moved.shape) == (12, 9)


def test_update_from_search_trains_on_the_search_sample_moved_by_the_shift():
    rng = np.random.default_rng(5)
    x = smooth_features(rng)
    search = np.roll(x, (2, -3), axis=(0, 1)) + 0.1 * rng.standard_normal(x.shape)
    shift = (2.0, -3.0)  # where the target was found, from the patch centre
    moved, resampled = preset_like_filter(), preset_like_filter()
    moved.initialize(x)
    resampled.initialize(x)
    with pytest.raises(RuntimeError, match="needs a response"):
        moved.update_from_search(shift)
    moved.response(search)
    moved.update_from_search(shift)
    # the windowed search sample rolled by -shift: the found target at the centre
    windowed = search * hann_window(x.shape[:2])[:, :, None]
    resampled.train(fft.rfft2(np.roll(windowed, (-2, 3), axis=(0, 1)), axes=(0, 1)))
    expected = resampled.filter_spectrum
    np.testing.assert_allclose(moved.filter_spectrum, expected, atol=1e-5 * np.abs(expected).max())
    # the other direction is another filter: the comparison can fail
    wrong = preset_like_filter()
    wrong.initialize(x)
    wrong.train(fft.rfft2(np.roll(windowed, (2, -3), axis=(0, 1)), axes=(0, 1)))
    assert np.abs(wrong.filter_spectrum - expected).max() > 1e-2 * np.abs(expected).max()


def test_a_batch_of_samples_gets_the_single_responses():
    rng = np.random.default_rng(6)
    x = smooth_features(rng)
    stack = np.stack([zoom_about_centre(x, f) for f in (0.98, 1.0, 1.02)] + [x[::-1]])
    learner = preset_like_filter()
    learner.initialize(x)
    batch = learner.response(stack)
    assert batch.shape == (4, 20, 24)
    for sample, response in zip(stack, batch, strict=True):
        np.testing.assert_allclose(response, learner.response(sample), rtol=1e-6, atol=1e-9)
    # learning from the batch's third sample is learning from that sample alone
    from_batch, single = preset_like_filter(), preset_like_filter()
    for learner in (from_batch, single):
        learner.initialize(x)
    from_batch.response(stack)
    from_batch.update_from_search((1.0, -1.0), index=2)
    single.response(stack[2])
    single.update_from_search((1.0, -1.0))
    np.testing.assert_allclose(from_batch.filter_spectrum, single.filter_spectrum, rtol=1e-6)


# -- helpers ---------------------------------------------------------------------------------


def test_zoom_by_one_is_the_identity():
    grid = np.random.default_rng(7).standard_normal((9, 16, 3)).astype(np.float32)
    np.testing.assert_array_equal(zoom_about_centre(grid, 1.0), grid)


@pytest.mark.parametrize("factor", [2.0, 0.5])
def test_zoom_reads_at_factor_times_the_offset_with_the_edges_repeated(factor):
    rows, cols = 9, 16
    r, c = np.mgrid[0:rows, 0:cols].astype(np.float32)
    ramp = 100.0 * r + c  # bilinear interpolation is exact on it
    centre_r, centre_c = rows / 2 - 0.5, cols / 2 - 0.5  # cell centres at i + 1/2
    read_r = np.clip(centre_r + factor * (r - centre_r), 0, rows - 1)
    read_c = np.clip(centre_c + factor * (c - centre_c), 0, cols - 1)
    zoomed = zoom_about_centre(ramp, factor)
    np.testing.assert_allclose(zoomed, 100.0 * read_r + read_c, atol=1e-3)
    if factor == 2.0:
        assert zoomed[0, 0] == ramp[0, 0] and zoomed[-1, -1] == ramp[-1, -1]  # replicated
        np.testing.assert_allclose(zoomed[4, 7:9], [406.5, 408.5], atol=1e-3)


def test_zoom_keeps_a_grid_of_fourteen_float32_channels():
    # the preset's grid after the projection: gray 1 + HOG 10 + Color Names 3
    grid = np.random.default_rng(8).standard_normal((20, 24, 14)).astype(np.float32)
    zoomed = zoom_about_centre(grid, 1.03)
    assert zoomed.shape == grid.shape and zoomed.dtype == np.float32
    for k in (0, 5, 13):
        np.testing.assert_allclose(zoomed[..., k], zoom_about_centre(grid[..., k], 1.03), atol=1e-6)
    assert zoom_about_centre(grid[..., :1], 1.03).shape == (20, 24, 1)


def test_block_projection_is_block_diagonal_and_orthonormal_per_block():
    layout = (("gray", 1), ("hog", 31), ("cn", 10))  # the preset's feature layout
    rng = np.random.default_rng(9)
    sample = rng.standard_normal((20, 24, 42)) * rng.uniform(0.1, 3.0, 42) + 5.0
    # the HOG block's variance lies mostly along two directions
    directions, _ = np.linalg.qr(rng.standard_normal((31, 2)))
    sample[..., 1:32] += 20.0 * rng.standard_normal((20, 24, 2)) @ directions.T
    projection = block_projection(sample, layout, {"hog": 10, "cn": 3})
    assert projection.shape == (42, 1 + 10 + 3) and projection.dtype == np.float32
    blocks = [
        (slice(0, 1), slice(0, 1)),
        (slice(1, 32), slice(1, 11)),
        (slice(32, 42), slice(11, 14)),
    ]
    rest = np.ones(projection.shape, bool)
    for rows, cols in blocks:
        block = projection[rows, cols]
        np.testing.assert_allclose(block.T @ block, np.eye(block.shape[1]), atol=1e-5)
        rest[rows, cols] = False
    np.testing.assert_array_equal(projection[rest], 0.0)  # block-diagonal
    assert projection[0, 0] == 1.0  # gray is not compressed: passed unchanged
    # the HOG block spans the 10 principal components of its centred channels
    hog = projection[1:32, 1:11].astype(np.float64)
    channels = sample[..., 1:32].reshape(-1, 31)
    centred = channels - channels.mean(axis=0)
    _, vectors = np.linalg.eigh(centred.T @ centred)  # ascending
    top = vectors[:, -10:]
    np.testing.assert_allclose(hog @ hog.T, top @ top.T, atol=1e-5)
    np.testing.assert_allclose(hog @ (hog.T @ directions), directions, atol=0.05)  # strong pair

    unchanged = block_projection(sample, layout, {"hog": 40})  # more than it has: all kept
    assert unchanged.shape == (42, 42)
    np.testing.assert_array_equal(unchanged, np.eye(42, dtype=np.float32))


def test_apce_is_high_for_one_sharp_peak_and_low_for_noise():
    peak = np.zeros((30, 30))
    peak[15, 15] = 1.0
    noise = np.random.default_rng(10).standard_normal((30, 30))
    sharp = average_peak_to_correlation_energy(peak)
    assert sharp == pytest.approx(900.0)  # 1 / mean of (F - F_min)^2 = cells
    assert sharp > 50 * average_peak_to_correlation_energy(noise)
    assert average_peak_to_correlation_energy(np.full((30, 30), 0.3)) == 0.0  # no peak at all


# -- configuration ---------------------------------------------------------------------------

STRCF = PRESETS["strcf_hog_cn"]


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"search_scales": 4}, "search_scales must be odd"),
        ({"search_scales": 0}, "search_scales must be odd"),
        ({"learner": "rcsk", "compressed_features": ()}, "search_scales > 1 needs learner"),
        ({"scale": ScaleConfig()}, "replaces the scale filter"),
        ({"search_scale_step": 1.0}, "search_scale_step must be > 1"),
        ({"compressed_features": (("hog", 10), ("lab", 3))}, "compressed_features: 'lab'"),
        ({"compressed_features": (("hog", 0),)}, "dimensions must be >= 1"),
        ({"compressed_dim": 2}, "compressed_dim needs a kernel learner"),
        ({"temporal_regularization": -1.0}, "temporal_regularization must be >= 0"),
        ({"peak_ratio": -0.1}, "must be >= 0"),
    ],
)
def test_bad_strcf_configuration_is_refused(fields, message):
    with pytest.raises(ValueError, match=message):
        dataclasses.replace(STRCF, **fields)


def test_compressed_features_need_strcf():
    with pytest.raises(ValueError, match="compressed_features needs learner 'strcf'"):
        CorrelationConfig(learner="rcsk", feature="hog+cn", compressed_features=(("cn", 3),))


@pytest.mark.parametrize("fields", [{"iterations": 0}, {"step": 0.0}, {"maximum": -1.0}])
def test_bad_admm_schedule_is_refused(fields):
    with pytest.raises(ValueError):
        AdmmSchedule(**fields)


def test_the_preset_schedule_is_the_reference_one():
    assert AdmmSchedule().penalties() == [1.0, 0.1]
    assert AdmmSchedule(iterations=4, initial=0.01, maximum=1.0, step=10.0).penalties() == (
        pytest.approx([0.01, 0.1, 1.0, 1.0])
    )


# -- the tracker -----------------------------------------------------------------------------


def textured(rng, shape, sigma):
    """Smoothed colour noise stretched to 0..255."""
    noise = ndimage.gaussian_filter(rng.standard_normal(shape), (sigma, sigma, 0))
    noise -= noise.min()
    return (255 * noise / noise.max()).astype(np.uint8)


def paste(frame, image, x, y):
    """``image`` onto ``frame`` with its top-left corner at (x, y), clipped to the frame."""
    h, w = image.shape[:2]
    top, left = max(y, 0), max(x, 0)
    bottom, right = min(y + h, frame.shape[0]), min(x + w, frame.shape[1])
    if bottom > top and right > left:
        frame[top:bottom, left:right] = image[top - y : bottom - y, left - x : right - x]


def covered(box, other):
    """The share of ``box``'s area (x, y, w, h) that ``other`` covers."""
    w = max(min(box[0] + box[2], other[0] + other[2]) - max(box[0], other[0]), 0)
    h = max(min(box[1] + box[3], other[1] + other[3]) - max(box[1], other[1]), 0)
    return w * h / (box[2] * box[3])


def passing_occluder_scene(seed=4, frames=60):
    """A reddish textured target (48 x 40) moving right and down over a textured background;
    a bluish textured occluder (26 x 56) drops onto its left half (frames 5-10), moves with it
    covering 54% of it (frames 11-21, while the target keeps moving), then goes off to the left
    as the target goes on to the right (uncovered from frame 26).

    Returns the frames and the target's and the occluder's boxes per frame."""
    rng = np.random.default_rng(seed)
    background = textured(rng, (240, 320, 3), 3.0)
    target = textured(rng, (40, 48, 3), 2.0)
    target[..., 0] = np.clip(target[..., 0].astype(int) + 60, 0, 255)
    occluder = textured(rng, (56, 26, 3), 1.5)
    occluder[..., 2] = np.clip(occluder[..., 2].astype(int) + 80, 0, 255)
    enter, hold = 12, 10

    def target_at(t):
        return 30 + 3.0 * t, 90 + 0.8 * t

    images, truth, occluders = [], [], []
    for t in range(frames):
        x, y = target_at(t)
        if t < enter + hold:
            ox, oy = x, y - 8 - 6.0 * max(enter - t, 0)  # dropping in, then moving along
        else:
            left_at = target_at(enter + hold - 1)
            ox, oy = left_at[0] - 3.0 * (t - enter - hold + 1), left_at[1] - 8
        frame = background.copy()
        paste(frame, target, round(x), round(y))
        paste(frame, occluder, round(ox), round(oy))
        images.append(frame)
        truth.append((round(x), round(y), 48, 40))
        occluders.append((round(ox), round(oy), 26, 56))
    return images, np.array(truth, float), np.array(occluders, float)


def test_the_preset_keeps_a_half_occluded_target_and_not_the_occluder():
    """Measured (seed 4): centre error at most 1.5 px over the 60 frames, overlap 0.94 or more
    once the occluder has gone. The scene is a trap: the thesis's grayscale trackers
    (mosse_gray, rcsk_gray) leave with the occluder (232 px off at the end), and so does this
    preset with its spatial penalty made uniform (182 px), or with mu 0 (15 px)."""
    images, truth, occluders = passing_occluder_scene()
    cover = np.array([covered(t, o) for t, o in zip(truth, occluders, strict=True)])
    # the scene is what it claims: about half of the target hidden for 10+ frames, then free
    assert 0.5 < cover.max() < 0.6
    assert np.sum(cover >= 0.45) >= 10
    free = np.arange(len(cover)) > np.flatnonzero(cover > 0).max()
    assert free.sum() >= 30

    tracker = CorrelationTracker(PRESETS["strcf_hog_cn"])
    tracker.initialize(images[0], Box(*truth[0]))
    boxes = np.array([truth[0]] + [tracker.update(f).box.as_array() for f in images[1:]])
    errors = center_location_error(boxes, truth)
    assert errors.max() < 8.0, f"max centre error {errors.max():.1f} px"
    assert errors[-1] < 4.0
    # after the occluder has gone, the box is on the target and nowhere near the occluder
    assert np.nanmin(iou(boxes[free], truth[free])) > 0.7
    np.testing.assert_array_equal(iou(boxes[free], occluders[free]), 0.0)


def hidden_target_scene(seed=0, frames=40):
    """A textured target (40 x 32) moving right at 3 px a frame behind a static occluder
    (64 x 60): partly hidden from frame 17, wholly in frames 30-38."""
    rng = np.random.default_rng(seed)
    background = textured(rng, (240, 320, 3), 3.0)
    target = textured(rng, (32, 40, 3), 2.0)
    target[..., 0] = np.clip(target[..., 0].astype(int) + 60, 0, 255)
    occluder = textured(rng, (60, 64, 3), 1.5)
    occluder[..., 2] = np.clip(occluder[..., 2].astype(int) + 80, 0, 255)
    images, truth = [], []
    for t in range(frames):
        x = 60 + 3 * t
        frame = background.copy()
        paste(frame, target, x, 110)
        paste(frame, occluder, 150, 100)
        images.append(frame)
        truth.append((x, 110, 40, 32))
    return images, np.array(truth, float), (150, 100, 64, 60)


def test_a_hidden_target_is_reported_occluded():
    """The preset's own failure signal (LMCF's peak test at 0.45, the APCE test off) fires on
    every wholly hidden frame and on none of the clean frames before (measured, seeds 0-7:
    flagged from cover 0.6-0.7 on; the hidden frames' peaks at most 0.2 of the clean ones').
    With apce_ratio 0.7 added it also flagged 3-15 of the 17 clean frames of every seed, so
    the preset as it is is the one tested."""
    images, truth, occluder = hidden_target_scene()
    cover = np.array([covered(box, occluder) for box in truth])
    hidden = np.flatnonzero(cover == 1.0)
    clean = np.arange(np.flatnonzero(cover > 0)[0])
    assert len(hidden) >= 5 and len(clean) >= 15

    config = PRESETS["strcf_hog_cn"]
    assert config.peak_ratio == 0.45 and config.apce_ratio == 0.0
    tracker = CorrelationTracker(config)
    tracker.initialize(images[0], Box(*truth[0]))
    outputs = [None] + [tracker.update(f) for f in images[1:]]
    occluded = np.array([False] + [o.occluded for o in outputs[1:]])
    assert not occluded[clean].any(), f"clean frames flagged: {np.flatnonzero(occluded[clean])}"
    assert occluded[hidden].sum() >= len(hidden) // 2, f"flagged: {np.flatnonzero(occluded)}"
    # a hidden target's response is lower than a visible one's
    peaks = np.array([np.nan] + [o.peak for o in outputs[1:]])
    assert np.nanmax(peaks[hidden]) < 0.45 * np.nanmean(peaks[clean])


@pytest.mark.slow
def test_the_preset_stays_on_the_deer(shared_data):
    """OTB Deer (71 frames, a deer leaping, fast motion and blur): measured mean overlap 0.77
    (success AUC 0.76, lowest overlap of a frame 0.62; with mu 15, the paper's: 0.79, 0.78,
    0.67); the floor is 0.15 below."""
    sequence = load_otb_sequence(shared_data / "otb" / "Deer")
    frames = [read_frame(p) for p in sequence.frame_paths]
    truth = sequence.ground_truth
    assert len(frames) == 71
    tracker = CorrelationTracker(PRESETS["strcf_hog_cn"])
    tracker.initialize(frames[0], Box(*truth[0]))
    boxes = np.array([truth[0]] + [tracker.update(f).box.as_array() for f in frames[1:]])
    overlaps = iou(boxes, truth)
    assert np.nanmean(overlaps) > 0.62, f"mean overlap {np.nanmean(overlaps):.3f}"
    assert np.nanmin(overlaps) > 0.3  # never lost on the way


# -- bad input -------------------------------------------------------------------------------


def test_a_grayscale_frame_is_refused_with_a_clear_message():
    images, truth, _ = hidden_target_scene(frames=2)
    gray = images[0].mean(axis=2).astype(np.uint8)
    with pytest.raises(ValueError, match=r"needs an RGB frame \(H, W, 3\), got shape \(240, 320\)"):
        CorrelationTracker(PRESETS["strcf_hog_cn"]).initialize(gray, Box(*truth[0]))
    tracker = CorrelationTracker(PRESETS["strcf_hog_cn"])
    tracker.initialize(images[0], Box(*truth[0]))
    with pytest.raises(ValueError, match="needs an RGB frame"):
        tracker.update(images[1].mean(axis=2).astype(np.uint8))


def test_a_frame_of_another_size_is_refused_in_update():
    images, truth, _ = hidden_target_scene(frames=2)
    tracker = CorrelationTracker(PRESETS["strcf_hog_cn"])
    tracker.initialize(images[0], Box(*truth[0]))
    with pytest.raises(ValueError, match=r"the frame is 160x120, but .* 320x240 frame"):
        tracker.update(images[1][:120, :160])
    assert not tracker.update(images[1]).occluded  # and it goes on with the right size
