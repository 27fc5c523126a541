"""Kernel correlations of periodic feature maps, computed with FFTs (thesis §2.2.4).

For feature maps ``f, g`` in ``l^D_p(M, N)`` (arrays of shape ``(M, N, D)``), a shift-invariant
kernel evaluated at every cyclic shift of ``f`` against ``g``,
``u(m, n) = kappa(tau_{-m,-n} f, g)``, costs ``O(D MN log MN)`` through the FFT:

* inner-product kernels, eq. 2.15: ``u = k(F^-1{sum_d F^d conj(G^d)})``;
* radial-basis kernels, eq. 2.17: ``u = k(||f||^2 + ||g||^2 - 2 F^-1{sum_d F^d conj(G^d)})``.

Inner products are divided by ``MND`` so that the thesis's constants (``sigma_kappa`` of
eq. 2.23, lambda) mean the same whatever the patch size and feature count. Spectra are kept in
the half-plane form of the real FFT (``scipy.fft.rfft2``): every signal here is real.
"""

from __future__ import annotations

import numpy as np
from scipy import fft

from tracking.correlation.config import KernelName


def spectrum(features: np.ndarray) -> np.ndarray:
    """Real 2-D FFT of each feature layer: ``(M, N, D) -> (M, N//2 + 1, D)`` complex."""
    return fft.rfft2(features, axes=(0, 1))


def inverse(spectrum_: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Inverse of :func:`spectrum` for a single layer ``(M, N//2 + 1) -> (M, N)`` real."""
    return fft.irfft2(spectrum_, s=shape, axes=(0, 1))


def kernel_correlation_spectrum(
    f: np.ndarray,
    f_hat: np.ndarray,
    g: np.ndarray,
    g_hat: np.ndarray,
    kernel: KernelName,
    *,
    sigma: float = 0.2,
    poly_offset: float = 1.0,
    poly_degree: int = 2,
) -> np.ndarray:
    """Spectrum ``U = F{u}`` of ``u(m, n) = kappa(tau_{-m,-n} f, g)`` (eq. 2.15, 2.17, 2.23).

    Parameters
    ----------
    f, g:
        Feature maps, real, shape ``(M, N, D)``.
    f_hat, g_hat:
        Their spectra from :func:`spectrum`.
    kernel:
        ``"linear"``: ``<f, g> / MND``; ``"polynomial"``: ``(<f, g> / MND + offset)^degree``;
        ``"gaussian"``: ``exp(-||f - g||^2 / (sigma^2 MND))``, eq. 2.23.

    Returns
    -------
    ndarray, complex, shape ``(M, N//2 + 1)``
    """
    rows, cols, dims = f.shape
    scale = 1.0 / (rows * cols * dims)
    # sum_d F^d conj(G^d): the spectrum of the cyclic cross-correlation <tau_{-m,-n} f, g>.
    cross = np.einsum("ijk,ijk->ij", f_hat, np.conj(g_hat))
    if kernel == "linear":
        return cross * scale
    inner = inverse(cross, (rows, cols))
    if kernel == "polynomial":
        return fft.rfft2((inner * scale + poly_offset) ** poly_degree)
    if kernel == "gaussian":
        # ||tau f - g||^2 = ||f||^2 + ||g||^2 - 2 <tau f, g>; rounding can make it slightly < 0.
        distance = np.maximum(float(np.vdot(f, f)) + float(np.vdot(g, g)) - 2.0 * inner, 0.0)
        return fft.rfft2(np.exp(-distance * (scale / sigma**2)))
    raise ValueError(f"unknown kernel {kernel!r}")
