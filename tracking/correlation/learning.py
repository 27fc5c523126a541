"""Appearance learning and detection of MOSSE, CSK and RCSK (thesis §2.1-2.3, Algorithms 2.1, 4.2).

Every learner takes unwindowed feature maps ``(M, N, D)``, applies the Hann window itself (after
projecting, when the dimensionality is reduced, as Algorithm 4.2 requires) and returns the
correlation output ``y_hat`` over the patch. Spectra are half-plane real FFTs (see
:mod:`tracking.correlation.kernels`); products and quotients of spectra of real signals stay
spectra of real signals, so every update below holds element-wise in that form.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from tracking.correlation.config import CorrelationConfig
from tracking.correlation.kernels import inverse, kernel_correlation_spectrum, spectrum
from tracking.correlation.projection import AdaptiveProjection
from tracking.correlation.signals import gaussian_label, hann_window


class CorrelationFilter(Protocol):
    """A learner: trained on patches centred on the target, evaluated on search patches."""

    def initialize(self, x: np.ndarray) -> None:
        """Train from scratch on the first sample ``x`` (``(M, N, D)``, target centred)."""
        ...

    def update(self, x: np.ndarray) -> None:
        """Blend in a new sample with the learning rate gamma."""
        ...

    def response(self, z: np.ndarray) -> np.ndarray:
        """Correlation output ``y_hat`` (``(M, N)``) over the search patch ``z``."""
        ...


def _learnt(state: np.ndarray | None) -> np.ndarray:
    """A filter's learnt state, which its ``initialize`` sets; RuntimeError before that."""
    if state is None:
        raise RuntimeError("initialize() must be called first")
    return state


class MosseFilter:
    """MOSSE for multi-channel features: eq. 2.4 with the multi-channel solution of eq. 2.12.

    ``H^d = H_N^d / (H_D + lambda')`` with
    ``H_N^d <- (1 - gamma) H_N^d + gamma Y conj(X^d)`` and
    ``H_D <- (1 - gamma) H_D + gamma sum_d X^d conj(X^d)``; detection
    ``y_hat = F^-1{sum_d H^d Z^d}``. The regulariser is ``lambda' = lambda MND`` so that lambda
    weighs against the mean squared feature value, as in the kernels' ``MND`` normalisation.
    """

    def __init__(
        self, shape: tuple[int, int], target_size: tuple[float, float], config: CorrelationConfig
    ) -> None:
        self._shape = shape
        self._window = hann_window(shape)[:, :, None]
        self._label_hat = spectrum(gaussian_label(shape, target_size, config.label_sigma))
        self._gamma = config.learning_rate
        self._lambda = config.regularization
        self._numerator: np.ndarray | None = None
        self._denominator: np.ndarray | None = None
        self._lambda_scaled = 0.0

    def _terms(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x_hat = spectrum(x * self._window)
        numerator = self._label_hat[:, :, None] * np.conj(x_hat)  # Y conj(X^d)
        denominator = np.einsum("ijk,ijk->ij", x_hat, np.conj(x_hat)).real  # sum_d |X^d|^2
        return numerator, denominator

    def initialize(self, x: np.ndarray) -> None:
        self._numerator, self._denominator = self._terms(x)
        self._lambda_scaled = self._lambda * x.size

    def update(self, x: np.ndarray) -> None:
        learnt_numerator, learnt_denominator = _learnt(self._numerator), _learnt(self._denominator)
        numerator, denominator = self._terms(x)
        g = self._gamma
        self._numerator = (1 - g) * learnt_numerator + g * numerator  # eq. 2.4a
        self._denominator = (1 - g) * learnt_denominator + g * denominator  # eq. 2.4b

    def response(self, z: np.ndarray) -> np.ndarray:
        z_hat = spectrum(z * self._window)
        # H^d = H_N^d / (H_D + lambda)   (eq. 2.4c);   y_hat = F^-1{sum_d H^d Z^d}
        product = np.einsum("ijk,ijk->ij", _learnt(self._numerator), z_hat)
        return inverse(product / (_learnt(self._denominator) + self._lambda_scaled), self._shape)


class KernelFilter:
    """CSK (eq. 2.10-2.11) or the proposed RCSK (eq. 2.20-2.21), optionally with the adaptive
    dimensionality reduction of Algorithm 4.2.

    The learnt appearance ``x_hat`` is kept unwindowed and in all ``D1`` dimensions; each use
    projects it with the current ``B_t`` and windows it (Algorithm 4.2, lines 10, 17, 20).
    Without reduction ``B_t`` is the identity and this is Algorithm 2.1.

    * CSK: ``A <- (1 - gamma) A + gamma Y / (U_x + lambda)``.
    * RCSK: ``A_N <- (1 - gamma) A_N + gamma Y U_x``;
      ``A_D <- (1 - gamma) A_D + gamma U_x (U_x + lambda)``; ``A = A_N / A_D`` (eq. 2.21a-c).

    In both, ``x_hat <- (1 - gamma) x_hat + gamma x`` (eq. 2.21d) and detection is
    ``y_hat = F^-1{A U_z}`` with ``u_z(m, n) = kappa(z_{m,n}, x_hat)`` (eq. 2.11).
    """

    def __init__(
        self,
        shape: tuple[int, int],
        target_size: tuple[float, float],
        config: CorrelationConfig,
    ) -> None:
        if config.learner not in ("csk", "rcsk"):
            raise ValueError(f"KernelFilter implements 'csk' and 'rcsk', not {config.learner!r}")
        self._shape = shape
        self._config = config
        self._robust = config.learner == "rcsk"
        self._window = hann_window(shape)[:, :, None]
        self._label_hat = spectrum(gaussian_label(shape, target_size, config.label_sigma))
        self._projection = (
            AdaptiveProjection(config.compressed_dim, config.mu)
            if config.compressed_dim is not None
            else None
        )
        self._appearance: np.ndarray | None = None  # x_hat, unwindowed, D1 dims
        self._model: tuple[np.ndarray, np.ndarray] | None = None  # windowed x~_hat, its spectrum
        self._a_num: np.ndarray | None = None
        self._a_den: np.ndarray | None = None
        self._alpha: np.ndarray | None = None

    @property
    def coefficients(self) -> np.ndarray | None:
        """``A``, the spectrum of the classifier coefficients ``a`` (half-plane form)."""
        return self._alpha

    @property
    def projection(self) -> np.ndarray | None:
        """The current projection matrix ``B_t`` (``D1 x D2``), or ``None`` without reduction."""
        return None if self._projection is None else self._projection.basis

    def _project(self, x: np.ndarray) -> np.ndarray:
        """``w(m, n) B_t^T x(m, n)``: project the feature vectors, then window."""
        if self._projection is not None:
            x = x @ self._projection.basis
        return x * self._window

    def _kernel(self, f, f_hat, g, g_hat) -> np.ndarray:
        c = self._config
        return kernel_correlation_spectrum(
            f,
            f_hat,
            g,
            g_hat,
            c.kernel,
            sigma=c.kernel_sigma,
            poly_offset=c.polynomial_offset,
            poly_degree=c.polynomial_degree,
        )

    def _learn(self, x: np.ndarray, first: bool) -> None:
        appearance = _learnt(self._appearance)
        if self._projection is not None:
            self._projection.update(appearance)  # Algorithm 4.1 on x_hat^t
        x_tilde = self._project(x)
        x_tilde_hat = spectrum(x_tilde)
        u_x = self._kernel(x_tilde, x_tilde_hat, x_tilde, x_tilde_hat)
        # u_x is real and even, so U_x is real; dropping the imaginary rounding keeps A_D real.
        u_x = u_x.real
        lam, g, y = self._config.regularization, self._config.learning_rate, self._label_hat
        if self._robust:
            num, den = y * u_x, u_x * (u_x + lam)  # Y U_x,  U_x (U_x + lambda)
            if first:
                self._a_num, self._a_den = num, den
            else:
                self._a_num = (1 - g) * _learnt(self._a_num) + g * num  # eq. 2.21a
                self._a_den = (1 - g) * _learnt(self._a_den) + g * den  # eq. 2.21b
            # A = A_N / A_D (eq. 2.21c); a den of exactly 0 only where U_x = 0 and lambda = 0.
            self._alpha = self._a_num / np.where(self._a_den == 0, 1e-12, self._a_den)
        else:
            alpha = y / (u_x + lam)  # eq. 2.10
            self._alpha = alpha if first else (1 - g) * _learnt(self._alpha) + g * alpha
        model = self._project(appearance)
        self._model = (model, spectrum(model))

    def initialize(self, x: np.ndarray) -> None:
        self._appearance = x.astype(np.float32, copy=True)
        self._learn(x, first=True)

    def update(self, x: np.ndarray) -> None:
        g = self._config.learning_rate
        self._appearance = (1 - g) * _learnt(self._appearance) + g * x  # eq. 2.21d
        self._learn(x, first=False)

    def response(self, z: np.ndarray) -> np.ndarray:
        if self._model is None:
            raise RuntimeError("initialize() must be called first")
        z_tilde = self._project(z)
        model, model_hat = self._model
        u_z = self._kernel(z_tilde, spectrum(z_tilde), model, model_hat)
        return inverse(_learnt(self._alpha) * u_z, self._shape)  # eq. 2.11


def make_filter(
    shape: tuple[int, int], target_size: tuple[float, float], config: CorrelationConfig
) -> CorrelationFilter:
    """The learner the configuration names."""
    if config.learner == "mosse":
        return MosseFilter(shape, target_size, config)
    if config.learner == "strcf":
        from tracking.correlation.regularized import TemporalRegularizedFilter

        return TemporalRegularizedFilter(
            shape, target_size, config.label_sigma, config.temporal_regularization, config.admm
        )
    return KernelFilter(shape, target_size, config)
