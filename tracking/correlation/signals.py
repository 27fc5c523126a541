"""The fixed signals of a circulant-structure tracker: label function and window (thesis §2.4)."""

from __future__ import annotations

import numpy as np


def gaussian_label(shape: tuple[int, int], target_size: tuple[float, float], sigma_y: float):
    """Desired correlation output y, eq. 2.22.

    ``y(m, n) = exp(-((m - M/2)^2 + (n - N/2)^2) / (2 sigma_y^2 s1 s2))``: a Gaussian whose
    standard deviation is ``sigma_y * sqrt(s1 s2)``, peaking at the patch centre
    ``(floor(M/2), floor(N/2))`` where the target sits in a training patch.

    Parameters
    ----------
    shape:
        ``(M, N)``: rows and columns of the feature grid.
    target_size:
        ``(s1, s2)``: target height and width in the same grid units.
    sigma_y:
        The label bandwidth (Table 2.1: 1/16).

    Returns
    -------
    ndarray, float32, shape (M, N)
    """
    rows, cols = shape
    variance = sigma_y**2 * float(target_size[0]) * float(target_size[1])
    m = np.arange(rows, dtype=np.float64) - rows // 2
    n = np.arange(cols, dtype=np.float64) - cols // 2
    return np.exp(-0.5 * (m[:, None] ** 2 + n[None, :] ** 2) / variance).astype(np.float32)


def hann_window(shape: tuple[int, int]) -> np.ndarray:
    """Hann window, eq. 2.24: ``w(m, n) = sin^2(pi m / (M-1)) sin^2(pi n / (N-1))``.

    Returns
    -------
    ndarray, float32, shape (M, N)
    """
    return np.outer(_hann(shape[0]), _hann(shape[1])).astype(np.float32)


def _hann(length: int) -> np.ndarray:
    if length < 2:
        return np.ones(length)
    return np.sin(np.pi * np.arange(length) / (length - 1)) ** 2


def gaussian_label_1d(length: int, sigma: float) -> np.ndarray:
    """A one-dimensional Gaussian label centred at ``length // 2`` (the scale filter's)."""
    k = np.arange(length, dtype=np.float64) - length // 2
    return np.exp(-0.5 * (k / sigma) ** 2).astype(np.float32)


def peak_to_sidelobe_ratio(response: np.ndarray, peak: tuple[int, int], exclude: int = 5) -> float:
    """Peak-to-sidelobe ratio of a correlation response (Bolme et al. 2010, the MOSSE paper).

    The sidelobe is the response outside a ``(2 exclude + 1)``-wide square around the peak,
    taken circularly since the response is periodic.
    """
    rows, cols = response.shape
    mask = np.ones(response.shape, dtype=bool)
    r = np.arange(peak[0] - exclude, peak[0] + exclude + 1) % rows
    c = np.arange(peak[1] - exclude, peak[1] + exclude + 1) % cols
    mask[np.ix_(r, c)] = False
    sidelobe = response[mask]
    if sidelobe.size < 2:
        return 0.0
    std = float(sidelobe.std())
    return float((response[peak] - sidelobe.mean()) / max(std, 1e-12))


def average_peak_to_correlation_energy(response: np.ndarray) -> float:
    """APCE of a correlation response (Wang et al., CVPR 2017, eq. 8):
    ``|F_max - F_min|^2 / mean((F - F_min)^2)``.

    High for one sharp peak over a flat floor; low for a flat or many-peaked response, as when
    the target is hidden and the filter matches scattered background.
    """
    low = float(response.min())
    energy = float(np.mean((response - low) ** 2))
    return (float(response.max()) - low) ** 2 / max(energy, 1e-30)


def subpixel_peak(response: np.ndarray) -> tuple[float, float, tuple[int, int]]:
    """Location of the maximum of a periodic response, refined by a parabola per axis.

    Returns
    -------
    (row, col, integer_peak)
        The refined position (may be fractional) and the integer argmax.
    """
    rows, cols = response.shape
    r, c = np.unravel_index(int(np.argmax(response)), response.shape)
    centre = response[r, c]
    offsets = []
    for before, after in (
        (response[(r - 1) % rows, c], response[(r + 1) % rows, c]),
        (response[r, (c - 1) % cols], response[r, (c + 1) % cols]),
    ):
        # Vertex of the parabola through (-1, before), (0, centre), (1, after).
        curvature = before - 2.0 * centre + after
        offsets.append(0.0 if curvature >= 0 else 0.5 * (before - after) / curvature)
    return (
        r + float(np.clip(offsets[0], -0.5, 0.5)),
        c + float(np.clip(offsets[1], -0.5, 0.5)),
        (
            int(r),
            int(c),
        ),
    )
