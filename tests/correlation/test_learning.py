"""The closed-form learners minimise their costs (eq. 2.2 and 2.19), checked by brute force."""

import numpy as np
import pytest

from tracking.correlation.config import CorrelationConfig
from tracking.correlation.kernels import inverse
from tracking.correlation.learning import KernelFilter, MosseFilter
from tracking.correlation.signals import gaussian_label, hann_window

SHAPE = (6, 5)
TARGET = (2.0, 2.0)


def shift_matrix(x):
    """Rows are the cyclic shifts x_{m,n}(k, l) = x(k + m, l + n), flattened, in (m, n) order."""
    rows, cols = x.shape[:2]
    return np.stack(
        [np.roll(x, (-m, -n), axis=(0, 1)).ravel() for m in range(rows) for n in range(cols)]
    )


def samples(count, dims, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.standard_normal((*SHAPE, dims)) for _ in range(count)]


def mosse_brute_force(windowed, betas, y, lam):
    """argmin_h sum_j beta_j ||h * x_j - y||^2 + lam ||h||^2 (eq. 2.2) as normal equations."""
    n = windowed[0].size
    lhs, rhs = lam * np.eye(n), np.zeros(n)
    for x, beta in zip(windowed, betas, strict=True):
        s = shift_matrix(x)  # (h * x)(m, n) = <x_{m,n}, h>
        lhs += beta * s.T @ s
        rhs += beta * s.T @ y.ravel()
    return np.linalg.solve(lhs, rhs)


@pytest.mark.parametrize(
    ("dims", "count"),
    [
        (1, 3),  # eq. 2.3: one channel, three images weighted as in eq. 2.5
        (3, 1),  # eq. 2.12: three channels, one image
        # Several channels and several images: the running numerator / denominator is MOSSE's
        # approximation, not the minimiser, so there is no exact answer to compare with.
    ],
)
def test_mosse_minimises_eq_2_2(dims, count):
    gamma = 0.3
    config = CorrelationConfig(learner="mosse", learning_rate=gamma, regularization=0.05)
    xs = samples(count, dims)
    mosse = MosseFilter(SHAPE, TARGET, config)
    mosse.initialize(xs[0])
    for x in xs[1:]:
        mosse.update(x)
    window = hann_window(SHAPE)[:, :, None]
    betas = [(1 - gamma) ** 2, gamma * (1 - gamma), gamma][-count:] if count > 1 else [1.0]
    y = gaussian_label(SHAPE, TARGET, config.label_sigma)
    # The filter's lambda is scaled by MND (see MosseFilter); the brute force uses the same.
    lam = config.regularization * xs[0].size
    h = mosse_brute_force([x * window for x in xs], betas, y, lam)
    z = samples(1, dims, seed=9)[0]
    expected = (shift_matrix(z * window) @ h).reshape(SHAPE)
    np.testing.assert_allclose(mosse.response(z), expected, atol=1e-8)


def kernel_matrix(x, kernel, config):
    """K[(m,n),(k,l)] = kappa(x_{m,n}, x_{k,l}) from the definitions of §2.2.4."""
    shifts = shift_matrix(x)
    scale = 1.0 / x.size
    if kernel == "linear":
        return shifts @ shifts.T * scale
    sq = np.sum(shifts**2, axis=1)
    distance = sq[:, None] + sq[None, :] - 2 * shifts @ shifts.T
    return np.exp(-np.maximum(distance, 0) * scale / config.kernel_sigma**2)


@pytest.mark.parametrize("kernel", ["linear", "gaussian"])
def test_rcsk_minimises_eq_2_19(kernel):
    """a = argmin sum_j beta_j (||K_j a - y||^2 + lam a^T K_j a) solves
    (sum_j beta_j K_j (K_j + lam I)) a = sum_j beta_j K_j y."""
    gamma = 0.25
    config = CorrelationConfig(
        learner="rcsk", kernel=kernel, learning_rate=gamma, regularization=0.1, kernel_sigma=0.8
    )
    xs = samples(3, 2, seed=4)
    rcsk = KernelFilter(SHAPE, TARGET, config)
    rcsk.initialize(xs[0])
    for x in xs[1:]:
        rcsk.update(x)
    window = hann_window(SHAPE)[:, :, None]
    betas = [(1 - gamma) ** 2, gamma * (1 - gamma), gamma]
    y = gaussian_label(SHAPE, TARGET, config.label_sigma).ravel()
    n = y.size
    lhs, rhs = np.zeros((n, n)), np.zeros(n)
    for x, beta in zip(xs, betas, strict=True):
        k = kernel_matrix(x * window, kernel, config)
        lhs += beta * k @ (k + config.regularization * np.eye(n))
        rhs += beta * k @ y
    a = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    np.testing.assert_allclose(inverse(rcsk.coefficients, SHAPE).ravel(), a, atol=1e-6)


@pytest.mark.parametrize("kernel", ["linear", "gaussian"])
def test_csk_single_image_solves_regularised_least_squares(kernel):
    """eq. 2.10: a = argmin ||K a - y||^2 + lam a^T K a, i.e. (K + lam I) a = y."""
    config = CorrelationConfig(learner="csk", kernel=kernel, regularization=0.1, kernel_sigma=0.8)
    (x,) = samples(1, 3, seed=7)
    csk = KernelFilter(SHAPE, TARGET, config)
    csk.initialize(x)
    k = kernel_matrix(x * hann_window(SHAPE)[:, :, None], kernel, config)
    y = gaussian_label(SHAPE, TARGET, config.label_sigma).ravel()
    a = np.linalg.solve(k + config.regularization * np.eye(y.size), y)
    np.testing.assert_allclose(inverse(csk.coefficients, SHAPE).ravel(), a, atol=1e-6)


@pytest.mark.parametrize("learner", ["mosse", "csk", "rcsk"])
def test_response_to_training_sample_peaks_at_centre(learner):
    config = CorrelationConfig(learner=learner, kernel="gaussian")
    rng = np.random.default_rng(3)
    x = rng.standard_normal((32, 24, 2)).astype(np.float32)
    filt = MosseFilter((32, 24), (8, 6), config) if learner == "mosse" else None
    filt = filt or KernelFilter((32, 24), (8, 6), config)
    filt.initialize(x)
    response = filt.response(x)
    assert np.unravel_index(np.argmax(response), response.shape) == (16, 12)
