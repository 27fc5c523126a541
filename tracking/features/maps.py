"""Feature maps of image patches on a grid of cells: what a correlation filter is trained on.

A feature specification names components joined by ``+`` (``"gray+cn"``, ``"hog+cn"``). Per-pixel
components (the colour representations of thesis §3.1) are averaged over ``cell_size`` x
``cell_size`` cells; ``hog`` is computed on cells directly. The layers are stacked along the
last axis.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from tracking.features.colornames import ColorNameTable
from tracking.features.hog import NUM_FEATURES as HOG_DIM
from tracking.features.hog import hog_feature_map
from tracking.features.registry import CELL_FEATURES, FeatureExtractor, feature_components


@lru_cache(maxsize=4)
def shared_color_names(w2c_path: str | None) -> ColorNameTable:
    """One :class:`ColorNameTable` per configured source, shared by every tracker that asks.

    The embedded model's table is computed once per process instead of once per tracker.
    """
    return ColorNameTable.from_config(w2c_path)


class FeatureMap:
    """Turns an RGB (or grayscale) patch into a ``(H // c, W // c, D)`` float32 feature map.

    Parameters
    ----------
    spec:
        Components joined by ``+``; each one of ``tracking.features.registry.FEATURE_NAMES``
        or ``"hog"``.
    cell_size:
        ``c``, pixels per cell side. ``hog`` needs ``c >= 2``.
    color_names:
        The Color Names table for ``cn``; the process-wide embedded one when omitted.
    """

    def __init__(
        self, spec: str, cell_size: int = 1, color_names: ColorNameTable | None = None
    ) -> None:
        components = feature_components(spec)
        if "hog" in components and cell_size < 2:
            raise ValueError(f"the 'hog' feature needs cell_size >= 2, got {cell_size}")
        if cell_size < 1:
            raise ValueError(f"cell_size must be >= 1, got {cell_size}")
        self.spec = "+".join(components)
        self.cell_size = cell_size
        if color_names is None and "cn" in components:
            color_names = shared_color_names(None)
        self._color_names = color_names
        self._pixel = {
            name: FeatureExtractor(name, color_names=color_names)
            for name in components
            if name not in CELL_FEATURES
        }
        self._components = components
        self.layout = tuple((c, HOG_DIM if c == "hog" else self._pixel[c].dim) for c in components)
        """``(component, dimensions)`` of each layer block, in the order they are stacked."""
        self.dim = sum(d for _, d in self.layout)
        self.needs_color = any(c not in ("gray", "hog") for c in components)

    @classmethod
    def from_config(cls, config) -> FeatureMap:
        """The feature map a :class:`~tracking.correlation.CorrelationConfig` describes."""
        color_names = None
        if "cn" in config.feature.split("+"):
            color_names = shared_color_names(config.color_names_path)
        return cls(config.feature, config.cell_size, color_names)

    def derived(self, spec: str | None, cell_size: int) -> FeatureMap:
        """Other features (``None``: the same) on another cell size, sharing the Color Names
        table."""
        color_names = self._color_names
        if color_names is None and spec is not None and "cn" in spec.split("+"):
            color_names = shared_color_names(None)
        return FeatureMap(spec or self.spec, cell_size, color_names)

    def check_frame(self, frame: np.ndarray) -> None:
        """Raise ``ValueError`` when colour features meet a grayscale frame."""
        if self.needs_color and (frame.ndim != 3 or frame.shape[2] != 3):
            raise ValueError(
                f"feature {self.spec!r} needs an RGB frame (H, W, 3), got shape {frame.shape}"
            )

    def __call__(self, patch: np.ndarray) -> np.ndarray:
        """Feature map of ``patch`` (``(H, W, 3)`` RGB uint8, or ``(H, W)`` for gray/HOG only).

        Returns
        -------
        ndarray, float32, shape ``(H // c, W // c, D)``
        """
        c = self.cell_size
        rows, cols = patch.shape[0] // c, patch.shape[1] // c
        patch = patch[: rows * c, : cols * c]
        layers = []
        for name in self._components:
            if name == "hog":
                layers.append(hog_feature_map(patch, c))
                continue
            values = self._pixel[name](patch)
            if c > 1:  # the mean over each cell (INTER_AREA at a whole factor is exactly that)
                values = values.astype(np.float32, copy=False)
                values = cv2.resize(values, (cols, rows), interpolation=cv2.INTER_AREA)
                values = values.reshape(rows, cols, -1)
            layers.append(values)
        stacked = layers[0] if len(layers) == 1 else np.concatenate(layers, axis=2)
        return stacked.astype(np.float32, copy=False)
