"""Spatially and temporally regularised correlation filters (STRCF, Li et al., CVPR 2018).

Beyond the thesis, the line of work that followed it. SRDCF (Danelljan et al., ICCV 2015) let a
filter learn from a search region several times the target by penalising filter coefficients
far from the target instead of shrinking the patch; STRCF keeps that spatial penalty and replaces
SRDCF's sample history by a temporal term that ties each frame's filter to the previous one.
The filter ``f`` of frame ``t`` minimises (STRCF eq. 3, over ``D`` feature channels)::

    1/2 ||sum_d x_d * f_d - y||^2  +  T/2 sum_d ||w . f_d||^2  +  T mu/2 ||f - f_{t-1}||^2

with ``x`` the windowed training sample, ``*`` circular correlation, ``y`` the Gaussian label,
``w`` the spatial penalty and ``T = M N`` the grid's cells (the factor the reference code's
unnormalised DFT puts on the penalties, so that its constants keep their meaning). It is solved
by ADMM (STRCF eq. 5-10) with the split ``f = g``: the ``f`` step is a rank-one linear system per
frequency (Sherman-Morrison, eq. 8), the ``g`` step an element-wise division in the spatial
domain (eq. 9), then the multiplier and penalty updates (eq. 10). Each frame runs two
iterations from zero, as the reference does: far from converged (the tests measure it), but its
constants were chosen with that schedule, and the temporal term keeps frames consistent.

Like the reference implementation, the penalty window is binary: tiny (1e-3) on the target's
box and huge (1e5) elsewhere, so the filter is in effect cropped to the target's size while the
sample covers the whole search region: background around the target becomes negative training
data without the periodic boundary effects of a padded kernel filter.

Spectra are half-plane real FFTs (:mod:`tracking.correlation.kernels`); every per-frequency
system is independent, and the other half follows by Hermitian symmetry.
"""

from __future__ import annotations

import numpy as np
from scipy import fft

from tracking.correlation.config import AdmmSchedule
from tracking.correlation.signals import gaussian_label, hann_window

# The reference implementation's binary spatial penalty (run_STRCF.m): on the target, off it.
PENALTY_ON_TARGET = 1e-3
PENALTY_OFF_TARGET = 1e5


def target_penalty_window(shape: tuple[int, int], target_size: tuple[float, float]) -> np.ndarray:
    """The binary spatial penalty ``w`` of the reference STRCF, centred on the grid.

    Parameters
    ----------
    shape:
        ``(M, N)`` rows and columns of the filter's grid.
    target_size:
        ``(rows, cols)`` the target covers on that grid (fractional; floored as the reference
        code does, at least one cell).

    Returns
    -------
    ndarray, float64, ``(M, N)``: :data:`PENALTY_ON_TARGET` on the target's cells around the
    centre ``(M // 2, N // 2)``, :data:`PENALTY_OFF_TARGET` elsewhere.
    """
    window = np.full(shape, PENALTY_OFF_TARGET)
    extent = [min(max(int(s), 1), n) for s, n in zip(target_size, shape, strict=True)]
    starts = [n // 2 - e // 2 for e, n in zip(extent, shape, strict=True)]
    window[starts[0] : starts[0] + extent[0], starts[1] : starts[1] + extent[1]] = PENALTY_ON_TARGET
    return window


def solve_filter_step(
    x_hat: np.ndarray,
    y_hat: np.ndarray,
    g_hat: np.ndarray,
    h_hat: np.ndarray,
    previous_hat: np.ndarray,
    gamma: float,
    mu: float,
    cells: int,
) -> np.ndarray:
    """The ``f`` subproblem of STRCF (eq. 7-8), solved per frequency in closed form.

    At every frequency ``j`` the ``D``-vector ``f_j`` solves
    ``(x_j x_j^H + T (gamma + mu) I) f_j = x_j conj(y_j) + T (gamma g_j - h_j + mu f'_j)``
    where ``f'`` is the previous frame's filter; by Sherman-Morrison,
    ``f_j = (q_j - x_j (x_j^H q_j) / (T (gamma + mu) + x_j^H x_j)) / (gamma + mu)`` with
    ``q_j = x_j conj(y_j) / T + gamma g_j - h_j + mu f'_j``.

    Parameters
    ----------
    x_hat:
        Spectrum of the windowed training sample, ``(M, K, D)`` (``K`` columns of a half plane
        or a full plane).
    y_hat:
        Spectrum of the label, ``(M, K)``.
    g_hat, h_hat:
        The auxiliary variable and the Lagrange multiplier, ``(M, K, D)``.
    previous_hat:
        The previous frame's filter, ``(M, K, D)`` (zeros with ``mu = 0`` on the first frame).
    gamma, mu:
        The ADMM penalty and the temporal regularisation.
    cells:
        ``T = M N``, the grid's cell count.
    """
    total = gamma + mu
    q = x_hat * (np.conj(y_hat) / cells)[:, :, None] + gamma * g_hat - h_hat + mu * previous_hat
    projection = np.einsum("ijk,ijk->ij", np.conj(x_hat), q)  # x^H q
    energy = np.einsum("ijk,ijk->ij", np.conj(x_hat), x_hat).real  # x^H x
    return (q - x_hat * (projection / (cells * total + energy))[:, :, None]) / total


def solve_auxiliary_step(weighted: np.ndarray, window: np.ndarray, gamma: float) -> np.ndarray:
    """The ``g`` subproblem of STRCF (eq. 9) in the spatial domain:
    ``g = (gamma f + h) / (w^2 + gamma)`` element-wise, given ``weighted = gamma f + h``
    ``(M, N, D)`` (one inverse transform of ``gamma F + H`` gives it, by linearity)."""
    return weighted / (window**2 + gamma)[:, :, None]


class TemporalRegularizedFilter:
    """STRCF's learner, with the interface of :class:`~tracking.correlation.learning.
    CorrelationFilter`: trained on patches centred on the target, evaluated on search patches.

    Each frame's filter is solved from the new sample alone with the previous filter as the
    temporal anchor: no sample history and no learning rate (``mu`` sets how fast the model
    follows). The label peaks at the grid's origin and the penalty window is centred, as in the
    reference code; :meth:`response` shifts its output so that element ``(M // 2, N // 2)`` is
    the patch centre, like the other learners.

    Parameters
    ----------
    shape:
        ``(M, N)`` of the feature grid.
    target_size:
        ``(rows, cols)`` of the target on that grid.
    label_sigma:
        sigma_y of the label (eq. 2.22; STRCF: 1/16).
    mu:
        The temporal regularisation (STRCF: 15).
    schedule:
        The ADMM iterations and penalties of each frame.
    """

    def __init__(
        self,
        shape: tuple[int, int],
        target_size: tuple[float, float],
        label_sigma: float,
        mu: float,
        schedule: AdmmSchedule,
    ) -> None:
        self._shape = shape
        self._cells = shape[0] * shape[1]
        self._window = hann_window(shape)[:, :, None]
        label = np.fft.ifftshift(gaussian_label(shape, target_size, label_sigma))
        self._label_hat = fft.rfft2(label).astype(np.complex64)
        self._penalty = target_penalty_window(shape, target_size).astype(np.float32)
        self._mu = mu
        self._schedule = schedule
        self._filter_hat: np.ndarray | None = None
        self._search_hat: np.ndarray | None = None  # the last search sample's spectrum
        # Phase ramps of a one-cell shift along rows and columns (half-plane frequencies).
        self._row_phase = (2j * np.pi * np.fft.fftfreq(shape[0]))[:, None, None]
        self._col_phase = (2j * np.pi * np.fft.rfftfreq(shape[1]))[None, :, None]

    @property
    def filter_spectrum(self) -> np.ndarray | None:
        """The learnt filter ``f`` as a half-plane spectrum ``(M, N // 2 + 1, D)``."""
        return self._filter_hat

    def _spectrum(self, x: np.ndarray) -> np.ndarray:
        return fft.rfft2(x * self._window, axes=(0, 1))

    def train(self, x_hat: np.ndarray) -> None:
        """Solve for the filter from a windowed sample's spectrum ``x_hat`` (ADMM, eq. 5-10)."""
        first = self._filter_hat is None
        previous = np.zeros_like(x_hat) if self._filter_hat is None else self._filter_hat
        mu = 0.0 if first else self._mu  # nothing to stay close to on the first frame
        f_hat = np.zeros_like(x_hat)
        g_hat = np.zeros_like(x_hat)
        h_hat = np.zeros_like(x_hat)
        gammas = self._schedule.penalties()
        for i, gamma in enumerate(gammas):
            f_hat = solve_filter_step(
                x_hat, self._label_hat, g_hat, h_hat, previous, gamma, mu, self._cells
            )
            if i == len(gammas) - 1:
                break  # the filter is f; a last g and h would not be used
            weighted = fft.irfft2(gamma * f_hat + h_hat, s=self._shape, axes=(0, 1))
            g_hat = fft.rfft2(solve_auxiliary_step(weighted, self._penalty, gamma), axes=(0, 1))
            h_hat = h_hat + gamma * (f_hat - g_hat)
        self._filter_hat = f_hat.astype(np.complex64)

    def initialize(self, x: np.ndarray) -> None:
        self._filter_hat = None
        self.train(self._spectrum(x))

    def update(self, x: np.ndarray) -> None:
        self.train(self._spectrum(x))

    def update_from_search(self, shift: tuple[float, float], index: int = 0) -> None:
        """Train on the last search sample (of a batch: the one at ``index``) moved by
        ``shift`` (rows, columns; cells): the target found ``shift`` from the search patch's
        centre is then at the centre, as in a sample taken there, without sampling and
        transforming the frame again (ECO's ``shift_sample``). The window moves with it; for
        shifts of a few cells that is the only difference."""
        if self._search_hat is None:
            raise RuntimeError("update_from_search() needs a response() first")
        search = self._search_hat if self._search_hat.ndim == 3 else self._search_hat[index]
        ramp = np.exp(self._row_phase * shift[0] + self._col_phase * shift[1])
        self.train(search * ramp.astype(np.complex64))

    def response(self, z: np.ndarray) -> np.ndarray:
        """The response ``(M, N)`` to a search sample ``(M, N, D)``, or the responses
        ``(S, M, N)`` to a batch of samples ``(S, M, N, D)``."""
        if self._filter_hat is None:
            raise RuntimeError("initialize() must be called first")
        axes = (z.ndim - 3, z.ndim - 2)
        self._search_hat = fft.rfft2(z * self._window, axes=axes)
        product = np.einsum("...ijk,ijk->...ij", self._search_hat, np.conj(self._filter_hat))
        return np.fft.fftshift(fft.irfft2(product, s=self._shape), axes=axes)
