"""Scale estimation with a one-dimensional correlation filter over a scale pyramid.

Beyond the thesis: the discriminative scale-space filter of Danelljan, Häger, Khan and Felsberg
(BMVC 2014). Around the current position, ``S`` patches of the target size times
``a^n`` (``n = -(S-1)/2 .. (S-1)/2``) are resampled to one small size; their feature vectors form
the ``S`` samples of a one-dimensional signal of ``d``-dimensional features, and a MOSSE filter
(eq. 2.4 with the multi-channel form of eq. 2.12) over that signal finds the best scale.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft

from tracking.correlation.config import ScaleConfig
from tracking.correlation.patches import extract_patch
from tracking.correlation.signals import gaussian_label_1d
from tracking.features.maps import FeatureMap

# Per-pixel features are pooled over cells this large for the scale samples: the scale filter
# needs the coarse shape of the target, and pooling keeps d small.
_SCALE_CELL = 4


class ScaleFilter:
    """Finds the relative scale change of a target from frame to frame.

    Parameters
    ----------
    config:
        Scale pyramid and filter parameters.
    base_target:
        ``(w, h)`` of the target at scale 1, pixels.
    features:
        The tracker's feature map; the scale filter uses the same features on coarser cells.
    """

    def __init__(
        self, config: ScaleConfig, base_target: tuple[float, float], features: FeatureMap
    ) -> None:
        self._config = config
        self._base_target = base_target
        self._features = features.derived(config.feature, max(features.cell_size, _SCALE_CELL))
        # Per-pixel features can be computed once on a canvas holding every sample and averaged
        # over each sample's cells through an integral image; HOG needs the per-sample path.
        self._pixel_features = (
            None
            if "hog" in self._features.spec.split("+")
            else features.derived(self._features.spec, 1)
        )
        count = config.num_scales
        exponents = np.arange(count) - count // 2
        self._factors = config.scale_step**exponents
        label = gaussian_label_1d(count, math.sqrt(count) * config.label_sigma_factor)
        self._label_hat = fft.fft(label)
        self._window = np.hanning(count + 2)[1:-1, None].astype(np.float32)
        w, h = base_target
        shrink = min(1.0, math.sqrt(config.model_max_area / (w * h)))
        cell = self._features.cell_size
        self._model_size = (
            max(round(w * shrink / cell), 1) * cell,
            max(round(h * shrink / cell), 1) * cell,
        )
        # A target must keep a few pixels per side, whatever the scale bounds say; one that
        # starts with fewer must not be made larger for it (the bound stops at its own size).
        self._min_scale = min(max(config.min_scale_factor, 6.0 / min(w, h)), 1.0)
        self._max_scale = config.max_scale_factor
        self._numerator: np.ndarray | None = None
        self._denominator: np.ndarray | None = None
        # The last estimate's samples: when the scale does not change (most frames), the update
        # samples exactly the same patches, so they are reused instead of extracted again.
        self._last: tuple[np.ndarray, tuple[float, float], float, np.ndarray] | None = None

    def _spectrum(self, frame: np.ndarray, center: tuple[float, float], scale: float):
        """FFT over the scale axis of the windowed samples, ``(S, d)``."""
        if self._pixel_features is None:
            w, h = self._base_target
            samples = np.stack(
                [
                    self._features(
                        extract_patch(
                            frame, center, (w * scale * f, h * scale * f), self._model_size
                        )
                    ).ravel()
                    for f in self._factors
                ]
            )
        else:
            samples = self._pooled_samples(self._pixel_features, frame, center, scale)
        return fft.fft(samples * self._window, axis=0)

    def _pooled_samples(
        self,
        pixel_features: FeatureMap,
        frame: np.ndarray,
        center: tuple[float, float],
        scale: float,
    ):
        """All ``S`` samples at once: per-pixel features on one canvas covering the largest
        sample, then the mean over every cell of every sample from an integral image.

        Cell borders fall between canvas pixels; the integral image of piecewise-constant
        pixels is bilinear inside each pixel, so reading it bilinearly at the fractional
        borders gives exact areas. (Rounding the borders instead stamps the same pattern on
        every frame's samples, which the filter then learns to match at the unchanged scale.)
        """
        cell = self._features.cell_size
        cols, rows = self._model_size[0] // cell, self._model_size[1] // cell
        factors = self._factors
        w, h = self._base_target
        # Canvas pixels per image pixel: the smallest sample spans 2 * model_size pixels.
        density = 2.0 * self._model_size[0] / (w * scale * factors[0])
        extent = (w * scale * factors[-1], h * scale * factors[-1])
        canvas_size = (max(round(extent[0] * density), 2), max(round(extent[1] * density), 2))
        canvas = pixel_features(extract_patch(frame, center, extent, canvas_size))
        height, width = canvas.shape[:2]
        integral = np.zeros((height + 1, width + 1, canvas.shape[2]))
        integral[1:, 1:] = canvas.cumsum(0).cumsum(1)
        # Cell borders of every sample in canvas pixels: (S, cols + 1) and (S, rows + 1).
        xs = width / 2 + (w * scale * density * factors)[:, None] * np.linspace(-0.5, 0.5, cols + 1)
        ys = height / 2 + (h * scale * density * factors)[:, None] * np.linspace(
            -0.5, 0.5, rows + 1
        )
        corners = _bilinear(integral, np.clip(ys, 0, height), np.clip(xs, 0, width))
        # Sum over each cell from its four corners: (S, rows, cols, D).
        sums = corners[:, 1:, 1:] - corners[:, :-1, 1:] - corners[:, 1:, :-1] + corners[:, :-1, :-1]
        area = np.diff(ys, axis=1)[:, :, None] * np.diff(xs, axis=1)[:, None, :]
        return (sums / area[..., None]).reshape(len(factors), -1).astype(np.float32)

    def _terms(self, frame, center, scale) -> tuple[np.ndarray, np.ndarray]:
        last = self._last
        if last is not None and last[0] is frame and last[1] == center and last[2] == scale:
            x_hat = last[3]
        else:
            x_hat = self._spectrum(frame, center, scale)
        numerator = self._label_hat[:, None] * np.conj(x_hat)  # Y conj(X^d)
        denominator = np.einsum("sd,sd->s", x_hat, np.conj(x_hat)).real  # sum_d |X^d|^2
        return numerator, denominator

    def _learnt(self) -> tuple[np.ndarray, np.ndarray]:
        """The numerator and denominator learnt so far."""
        if self._numerator is None or self._denominator is None:
            raise RuntimeError("initialize the scale filter first")
        return self._numerator, self._denominator

    def initialize(self, frame: np.ndarray, center: tuple[float, float], scale: float) -> None:
        self._last = None
        self._numerator, self._denominator = self._terms(frame, center, scale)

    def update(self, frame: np.ndarray, center: tuple[float, float], scale: float) -> None:
        learnt_numerator, learnt_denominator = self._learnt()
        numerator, denominator = self._terms(frame, center, scale)
        self._last = None
        g = self._config.learning_rate
        self._numerator = (1 - g) * learnt_numerator + g * numerator  # eq. 2.4a
        self._denominator = (1 - g) * learnt_denominator + g * denominator  # eq. 2.4b

    def estimate(self, frame: np.ndarray, center: tuple[float, float], scale: float) -> float:
        """The new scale: the current one times the factor with the strongest response."""
        numerator, denominator = self._learnt()
        z_hat = self._spectrum(frame, center, scale)
        self._last = (frame, center, scale, z_hat)
        product = np.einsum("sd,sd->s", numerator, z_hat)
        response = fft.ifft(product / (denominator + self._config.regularization)).real
        best = int(np.argmax(response))
        return float(np.clip(scale * self._factors[best], self._min_scale, self._max_scale))


def _bilinear(table: np.ndarray, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """``table`` (``(H + 1, W + 1, D)``) read bilinearly at every pair of ``ys`` ``(S, R)`` and
    ``xs`` ``(S, C)`` of the same sample: ``(S, R, C, D)``."""
    y0 = np.minimum(np.floor(ys).astype(int), table.shape[0] - 2)
    x0 = np.minimum(np.floor(xs).astype(int), table.shape[1] - 2)
    wy = (ys - y0)[:, :, None, None]
    wx = (xs - x0)[:, None, :, None]
    r0, r1 = y0[:, :, None], y0[:, :, None] + 1
    c0, c1 = x0[:, None, :], x0[:, None, :] + 1
    top = table[r0, c0] * (1 - wx) + table[r0, c1] * wx
    bottom = table[r1, c0] * (1 - wx) + table[r1, c1] * wx
    return top * (1 - wy) + bottom * wy
