"""The circulant-structure single-target tracker (thesis Algorithms 2.1 and 4.2)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracking.correlation.config import CorrelationConfig
from tracking.correlation.learning import CorrelationFilter, make_filter
from tracking.correlation.patches import extract_patch, zoom_about_centre
from tracking.correlation.presets import PRESETS
from tracking.correlation.projection import block_projection
from tracking.correlation.regularized import TemporalRegularizedFilter
from tracking.correlation.scale import ScaleFilter
from tracking.correlation.signals import (
    average_peak_to_correlation_energy,
    peak_to_sidelobe_ratio,
    subpixel_peak,
)
from tracking.features.maps import FeatureMap
from tracking.types import Box, TrackerOutput, as_box, validate_box, validate_uint8_frame


@dataclass(slots=True)
class _Geometry:
    """Fixed at initialisation: how image pixels map onto the feature grid."""

    base_target: tuple[float, float]  # (w, h) of the target at scale 1, pixels
    base_patch: tuple[float, float]  # (w, h) of the padded patch at scale 1, pixels
    model_pixels: tuple[int, int]  # (w, h) the patch is resampled to, a multiple of the cell
    grid: tuple[int, int]  # (M, N) = rows, columns of the feature grid

    def pixels_per_cell(self, scale: float) -> tuple[float, float]:
        """Image pixels per grid cell along (x, y) at the given scale."""
        return (
            self.base_patch[0] * scale / self.grid[1],
            self.base_patch[1] * scale / self.grid[0],
        )


@dataclass(frozen=True, slots=True)
class ResponseMap:
    """A correlation response over a search patch, located in the image.

    Attributes
    ----------
    response:
        ``(M, N)`` correlation output ``y_hat``; element ``(M // 2, N // 2)`` lies at ``center``.
    center:
        ``(x, y)`` image position the patch was sampled around.
    step:
        ``(sx, sy)`` image pixels per response element.
    """

    response: np.ndarray
    center: tuple[float, float]
    step: tuple[float, float]

    def at(self, points: np.ndarray) -> np.ndarray:
        """The response at image positions ``points`` ``(K, 2)`` (x, y), bilinearly
        interpolated; positions outside the patch get the response's minimum."""
        rows, cols = self.response.shape
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        c = (points[:, 0] - self.center[0]) / self.step[0] + cols // 2
        r = (points[:, 1] - self.center[1]) / self.step[1] + rows // 2
        inside = (c >= 0) & (c <= cols - 1) & (r >= 0) & (r <= rows - 1)
        c0 = np.clip(np.floor(c).astype(int), 0, cols - 2)
        r0 = np.clip(np.floor(r).astype(int), 0, rows - 2)
        fc, fr = np.clip(c - c0, 0, 1), np.clip(r - r0, 0, 1)
        y = self.response
        top = y[r0, c0] * (1 - fc) + y[r0, c0 + 1] * fc
        bottom = y[r0 + 1, c0] * (1 - fc) + y[r0 + 1, c0 + 1] * fc
        values = top * (1 - fr) + bottom * fr
        return np.where(inside, values, float(y.min()))


class CorrelationTracker:
    """MOSSE, CSK or RCSK on any feature representation, with optional scale adaptation.

    One instance follows one target (see :class:`tracking.types.Tracker`). Per frame it samples
    a ``(1 + eta)``-times padded patch at the previous position, finds the correlation peak
    (Algorithm 2.1 lines 6-9), moves there, re-samples and learns (lines 10-12).

    Parameters
    ----------
    config:
        Every tunable number; defaults are the thesis's (Table 2.1). Or the name of one of
        :data:`~tracking.correlation.PRESETS` (``"rcsk_cn"``), as ``vtrack track --preset``.
    features:
        A ready feature map, to share one Color Names table between many trackers. Built from
        ``config`` when omitted.
    """

    def __init__(
        self, config: CorrelationConfig | str | None = None, *, features: FeatureMap | None = None
    ) -> None:
        self.config = _config(config)
        self._features = features or FeatureMap.from_config(self.config)
        self._filter: CorrelationFilter | None = None
        self._scale_filter: ScaleFilter | None = None
        self._geometry: _Geometry | None = None
        self._projection: np.ndarray | None = None
        self._center = (0.0, 0.0)
        self._scale = 1.0
        self._frame_size: tuple[int, ...] = ()
        self._confidence = _ConfidenceHistory(self.config.apce_ratio, self.config.peak_ratio)

    @property
    def feature_map(self) -> FeatureMap:
        return self._features

    def reset(self) -> None:
        self._filter = None
        self._scale_filter = None
        self._geometry = None

    def initialize(self, frame: np.ndarray, box: Box) -> None:
        """Learn the target in ``box`` of ``frame`` (Algorithm 2.1, lines 1-4).

        ``box`` may also be four numbers ``(x, y, w, h)``.

        Raises
        ------
        ValueError
            For an empty or wrongly shaped frame, a box of zero size, outside the frame or
            more than four times its size, or colour features on a grayscale frame.
        TypeError
            For a frame that is not uint8, or a box that is not a Box or four numbers.
        """
        frame = validate_uint8_frame(frame, "the correlation tracker")
        box = validate_box(as_box(box), frame.shape)
        self._features.check_frame(frame)
        self._frame_size = frame.shape[:2]
        self._geometry = self._plan_geometry(box)
        self._center = box.center
        self._scale = 1.0
        self._confidence = _ConfidenceHistory(self.config.apce_ratio, self.config.peak_ratio)
        g = self._geometry
        cell = self.config.cell_size
        target_in_cells = (
            box.h * g.model_pixels[1] / g.base_patch[1] / cell,
            box.w * g.model_pixels[0] / g.base_patch[0] / cell,
        )
        self._filter = make_filter(g.grid, target_in_cells, self.config)
        self._projection = None
        first = self._sample(frame, self._center, self._scale)
        if self.config.compressed_features:
            self._projection = block_projection(
                first, self._features.layout, dict(self.config.compressed_features)
            )
            first = first @ self._projection
        self._filter.initialize(first)

        self._scale_filter = None
        if self.config.scale is not None:
            self._scale_filter = ScaleFilter(self.config.scale, g.base_target, self._features)
            self._scale_filter.initialize(frame, self._center, self._scale)

    def update(self, frame: np.ndarray) -> TrackerOutput:
        """Locate the target in ``frame`` and learn from it (Algorithm 2.1, lines 6-12).

        ``frame`` must have the size of the first one (ValueError otherwise).
        """
        self._target("update")
        frame = validate_uint8_frame(frame, "the correlation tracker")
        if frame.shape[:2] != self._frame_size:
            # the target's position and patch were planned in the first frame's geometry
            (h0, w0), (h, w) = self._frame_size, frame.shape[:2]
            raise ValueError(
                f"the frame is {w}x{h}, but the target was learnt in a {w0}x{h0} frame: "
                "initialize the tracker again for frames of another size"
            )
        self._features.check_frame(frame)
        response, step, sample_scale, index = self._search(frame)
        row, col, peak = subpixel_peak(response)
        if not self.config.subpixel:
            row, col = float(peak[0]), float(peak[1])
        rows, cols = response.shape
        # The label peaks at (M//2, N//2): the peak's offset from there is the target's motion.
        # Offsets past half the patch wrap around (the response is periodic).
        d_row = (row - rows // 2 + rows / 2) % rows - rows / 2
        d_col = (col - cols // 2 + cols / 2) % cols - cols / 2
        height, width = frame.shape[:2]
        previous = self._center
        self._center = (
            float(np.clip(self._center[0] + d_col * step[0], 0, width - 1)),
            float(np.clip(self._center[1] + d_row * step[1], 0, height - 1)),
        )
        occluded = not self._confidence.accept(response)
        if not occluded:
            if self.config.search_scales > 1:
                self._scale = self._bounded_scale(sample_scale)
            if self._scale_filter is not None:
                self._scale = self._scale_filter.estimate(frame, self._center, self._scale)
            if isinstance(self._filter, TemporalRegularizedFilter) and self._scale == sample_scale:
                # the search sample, moved onto the target, is the training sample
                shift = (
                    (self._center[1] - previous[1]) / step[1],
                    (self._center[0] - previous[0]) / step[0],
                )
                self._filter.update_from_search(shift, index)
                if self._scale_filter is not None:
                    self._scale_filter.update(frame, self._center, self._scale)
            else:
                self.learn(frame)
        return TrackerOutput(
            box=self.box,
            peak=float(response[peak]),
            psr=peak_to_sidelobe_ratio(response, peak),
            occluded=occluded,
        )

    def _search(self, frame: np.ndarray) -> tuple[np.ndarray, tuple[float, float], float, int]:
        """The response at the current position: over one sample at the current scale, or
        (``search_scales`` > 1, STRCF) the best of a batch of samples around it.

        Returns the response, its image pixels per cell, the scale it was sampled at and that
        sample's index in the batch."""
        correlation_filter, geometry = self._target("update")
        c = self.config
        if c.search_scales == 1:
            found = self.respond(frame)
            return found.response, found.step, self._scale, 0
        exponents = np.arange(c.search_scales) - c.search_scales // 2
        factors = c.search_scale_step**exponents
        scales = self._scale * factors
        # One sample at the current scale, zoomed on the feature grid for the others: the
        # steps are a percent or two, and features cost five times the rest of a frame.
        x = self._sample(frame, self._center, self._scale)
        samples = np.stack([zoom_about_centre(x, f) for f in factors])
        responses = correlation_filter.response(samples)
        index = int(np.argmax(responses.reshape(len(scales), -1).max(axis=1)))
        scale = float(scales[index])
        return responses[index], geometry.pixels_per_cell(scale), scale, index

    def _bounded_scale(self, scale: float) -> float:
        """``scale`` kept where the target has at least 6 pixels a side (or its first size,
        if smaller) and fits in the frame (STRCF's bounds)."""
        w, h = self._target("update")[1].base_target
        low = min(6.0 / min(w, h), 1.0)
        high = max(min(self._frame_size[1] / w, self._frame_size[0] / h), 1.0)
        return float(np.clip(scale, low, high))

    def respond(
        self,
        frame: np.ndarray,
        center: tuple[float, float] | None = None,
        scale: float | None = None,
    ) -> ResponseMap:
        """The correlation response over the search patch at ``center`` and ``scale`` (default:
        the current ones), without moving or learning: for callers that fuse it with other
        evidence, like the particle filter of Part II."""
        correlation_filter, geometry = self._target("respond")
        center = self._center if center is None else center
        scale = self._scale if scale is None else scale
        response = correlation_filter.response(self._sample(frame, center, scale))
        return ResponseMap(response, center, geometry.pixels_per_cell(scale))

    def learn(
        self,
        frame: np.ndarray,
        center: tuple[float, float] | None = None,
        scale: float | None = None,
    ) -> None:
        """Learn the appearance at ``center`` and ``scale`` and make them the current target
        (Algorithm 2.1, lines 10-12; the scale filter learns too)."""
        correlation_filter, _ = self._target("learn")
        if center is not None:
            self._center = (float(center[0]), float(center[1]))
        if scale is not None:
            self._scale = float(scale)
        correlation_filter.update(self._sample(frame, self._center, self._scale))
        if self._scale_filter is not None:
            self._scale_filter.update(frame, self._center, self._scale)

    def _target(self, method: str) -> tuple[CorrelationFilter, _Geometry]:
        """The filter and geometry that ``initialize`` makes; RuntimeError before it."""
        if self._filter is None or self._geometry is None:
            raise RuntimeError(f"initialize() must be called before {method}()")
        return self._filter, self._geometry

    @property
    def box(self) -> Box:
        """The current target box."""
        if self._geometry is None:
            raise RuntimeError("the tracker has no target; call initialize()")
        w, h = self._geometry.base_target
        return Box.from_center(*self._center, w * self._scale, h * self._scale)

    def _sample(self, frame: np.ndarray, center: tuple[float, float], scale: float) -> np.ndarray:
        g = self._target("sample")[1]
        size = (g.base_patch[0] * scale, g.base_patch[1] * scale)
        x = self._features(extract_patch(frame, center, size, g.model_pixels))
        return x if self._projection is None else x @ self._projection

    def _plan_geometry(self, box: Box) -> _Geometry:
        """Patch size ``(M, N) = (1 + eta) s`` (§2.4.1), resampled down if above the area cap
        or up if its short side is below ``min_patch_side`` (never past the cap), and rounded
        to whole feature cells."""
        c = self.config
        patch_w, patch_h = box.w * (1.0 + c.padding), box.h * (1.0 + c.padding)
        if c.square_patch:  # the same area, as a square (STRCF's search region)
            patch_w = patch_h = math.sqrt(patch_w * patch_h)
        patch_w = max(patch_w, 2.0 * c.cell_size)
        patch_h = max(patch_h, 2.0 * c.cell_size)
        area = patch_w * patch_h
        fit = math.inf if c.max_patch_area is None else math.sqrt(c.max_patch_area / area)
        # Below the cap, a small target is enlarged until the patch's short side reaches
        # min_patch_side (or its area the cap): on a grid of a few cells the filter cannot tell
        # the target from its surroundings (a 12 x 9 px target on 4 px cells is lost in frames)
        resample = min(fit, max(c.min_patch_side / min(patch_w, patch_h), 1.0))
        cols = max(round(patch_w * resample / c.cell_size), 2)
        rows = max(round(patch_h * resample / c.cell_size), 2)
        # Keep the resampling isotropic: the patch in the image is exactly the model grid scaled.
        model = (cols * c.cell_size, rows * c.cell_size)
        base_patch = (model[0] / resample, model[1] / resample)
        return _Geometry((box.w, box.h), base_patch, model, (rows, cols))


class _ConfidenceHistory:
    """The failure signal of LMCF (Wang et al., CVPR 2017, §3.3): a frame is trusted when its
    response's APCE and peak both reach a fraction of their means over the frames before.

    The means run over every frame so far, the rejected ones included (as in the paper): during
    a long change of appearance they sink until frames are trusted again, so the tracker
    cannot freeze for good the way a fixed threshold makes it.
    """

    def __init__(self, apce_ratio: float, peak_ratio: float) -> None:
        self._ratios = (apce_ratio, peak_ratio)
        self._sums = np.zeros(2)
        self._count = 0

    def accept(self, response: np.ndarray) -> bool:
        """Record the frame's response; whether the tracker may trust it."""
        if not any(self._ratios):
            return True
        values = np.array([average_peak_to_correlation_energy(response), float(response.max())])
        ratios = np.asarray(self._ratios)
        passed = (values >= ratios * self._sums / max(self._count, 1)) | (ratios == 0)
        trusted = self._count == 0 or bool(passed.all())
        self._sums += values
        self._count += 1
        return trusted


def _config(config: object) -> CorrelationConfig:
    """A tracker's configuration from what its caller gave: a config, a preset's name, nothing."""
    if config is None:
        return CorrelationConfig()
    if isinstance(config, str):
        if config not in PRESETS:
            raise ValueError(f"unknown preset {config!r}; presets: {', '.join(PRESETS)}")
        return PRESETS[config]
    if not isinstance(config, CorrelationConfig):
        raise TypeError(
            f"config must be a CorrelationConfig or a preset's name, got {type(config).__name__}"
        )
    return config
