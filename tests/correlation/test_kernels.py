"""The FFT kernel correlations (eq. 2.15, 2.17, 2.23) against their spatial definitions."""

import numpy as np
import pytest

from tracking.correlation.kernels import inverse, kernel_correlation_spectrum, spectrum


def direct_kernel_correlation(f, g, kernel, sigma=0.2, offset=1.0, degree=2):
    """u(m, n) = kappa(tau_{-m,-n} f, g) summed pixel by pixel; tau_{-m,-n} f = roll by (-m, -n)."""
    rows, cols, dims = f.shape
    scale = 1.0 / (rows * cols * dims)
    out = np.empty((rows, cols))
    for m in range(rows):
        for n in range(cols):
            shifted = np.roll(f, (-m, -n), axis=(0, 1))
            if kernel == "gaussian":
                out[m, n] = np.exp(-np.sum((shifted - g) ** 2) * scale / sigma**2)
            else:
                inner = np.sum(shifted * g) * scale
                out[m, n] = inner if kernel == "linear" else (inner + offset) ** degree
    return out


@pytest.mark.parametrize(
    ("kernel", "shape"),
    [
        ("linear", (6, 7, 3)),  # inner product, eq. 2.15 with k = identity; odd width
        ("polynomial", (5, 8, 2)),  # eq. 2.15 with k(t) = (t + 1)^2; odd height
        ("gaussian", (8, 6, 4)),  # eq. 2.17 / 2.23
        ("gaussian", (7, 5, 1)),  # single channel, both sides odd
    ],
)
def test_fft_kernel_equals_direct_definition(kernel, shape):
    rng = np.random.default_rng(0)
    f = rng.standard_normal(shape)
    g = rng.standard_normal(shape)
    fast = inverse(
        kernel_correlation_spectrum(f, spectrum(f), g, spectrum(g), kernel, sigma=0.7),
        shape[:2],
    )
    np.testing.assert_allclose(fast, direct_kernel_correlation(f, g, kernel, sigma=0.7), atol=1e-10)


def test_gaussian_kernel_of_a_signal_with_itself_peaks_at_zero_shift():
    rng = np.random.default_rng(1)
    f = rng.standard_normal((9, 9, 2))
    u = inverse(kernel_correlation_spectrum(f, spectrum(f), f, spectrum(f), "gaussian"), (9, 9))
    assert np.unravel_index(np.argmax(u), u.shape) == (0, 0)
    assert u[0, 0] == pytest.approx(1.0)
