"""One place that maps feature names to extractors (thesis chapter 3 and §5.3).

``FeatureExtractor("gray+cn")`` — grayscale stacked with the 10-dim normalised Color Names, the
thesis's main configuration — or any single name of :data:`FEATURE_NAMES`, or several joined by
``+``. Every extractor returns ``float32 (H, W, D)`` with ``D = extractor.dim``.

Adding a feature (e.g. HOG from ``tracking/features/hog.py``, ``fhog(image, cell_size)``): add a
:class:`FeatureSpec` to ``_SPECS`` below (:data:`FEATURE_NAMES` follows it). A cell-based
feature sets ``cell_size`` (its output is ``(H // cell_size, W // cell_size, D)``); combinations
are only allowed between features of equal ``cell_size``. Import the module inside the compute
function so this registry does not depend on it until it is used.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from tracking.features import colorspaces as cs
from tracking.features.colornames import ColorNameTable

__all__ = ["FEATURE_NAMES", "FeatureExtractor", "FeatureSpec", "feature_dim"]


@dataclass(frozen=True, slots=True)
class FeatureSpec:
    """How to compute one named feature.

    Attributes
    ----------
    name:
        Registry name, e.g. ``"cn"``.
    dim:
        Number of output channels D.
    needs_rgb:
        True if the feature is undefined on grayscale frames.
    compute:
        ``compute(image, color_names) -> float32 (H', W', dim)``; ``color_names`` is the
        extractor's table (only Color Names uses it).
    cell_size:
        Pixels per output cell along each axis: 1 for per-pixel maps (all colour features).
    """

    name: str
    dim: int
    needs_rgb: bool
    compute: Callable[[np.ndarray, ColorNameTable | None], np.ndarray]
    cell_size: int = 1


def _pixelwise(
    function: Callable[[np.ndarray], np.ndarray],
) -> Callable[[np.ndarray, ColorNameTable | None], np.ndarray]:
    # Adapts a colorspaces function (image -> map) to the spec signature.
    return lambda image, _color_names: function(image)


def _color_names_map(image: np.ndarray, color_names: ColorNameTable | None) -> np.ndarray:
    # FeatureExtractor gives every feature that has "cn" a table.
    assert color_names is not None, "Color Names need a table"
    return color_names(image)


_SPECS: MappingProxyType[str, FeatureSpec] = MappingProxyType(
    {
        spec.name: spec
        for spec in (
            FeatureSpec("gray", 1, False, _pixelwise(cs.gray_features)),
            FeatureSpec("rgb", 3, True, _pixelwise(cs.rgb_features)),
            FeatureSpec("lab", 3, True, _pixelwise(cs.lab_features)),
            FeatureSpec("ycbcr", 3, True, _pixelwise(cs.ycbcr_features)),
            FeatureSpec("rg", 2, True, _pixelwise(cs.rg_features)),
            FeatureSpec("hsv", 3, True, _pixelwise(cs.hsv_features)),
            FeatureSpec("opponent", 3, True, _pixelwise(cs.opponent_features)),
            FeatureSpec("c", 3, True, _pixelwise(cs.c_features)),
            FeatureSpec("hue", cs.HUE_BINS, True, _pixelwise(cs.hue_features)),
            FeatureSpec("opp_angle", cs.HUE_BINS, True, _pixelwise(cs.opp_angle_features)),
            FeatureSpec("so", 6 * len(cs.SO_SCALES), True, _pixelwise(cs.so_features)),
            # §3.2.1: the 10-dim orthonormal normalisation of Color Names, one table lookup.
            FeatureSpec("cn", 10, True, _color_names_map),
            # HOG hook (not registered yet; hog.py is owned elsewhere), e.g.:
            # FeatureSpec("hog", 31, False, _hog, cell_size=4) with
            # def _hog(image, _cn): from tracking.features.hog import fhog; return fhog(image, 4)
        )
    }
)

FEATURE_NAMES: tuple[str, ...] = tuple(_SPECS)
"""Single feature names; combine them with ``+`` (e.g. ``"gray+cn"``)."""

CELL_FEATURES: tuple[str, ...] = ("hog",)
"""Features computed per cell of several pixels (:class:`~tracking.features.maps.FeatureMap`
stacks them with the per-pixel ones above)."""


def feature_components(spec: str) -> tuple[str, ...]:
    """The components of a feature spec such as ``"gray+cn"`` (ValueError for an unknown one)."""
    components = tuple(part.strip() for part in str(spec).split("+") if part.strip())
    valid = (*FEATURE_NAMES, *CELL_FEATURES)
    if not components or any(c not in valid for c in components):
        raise ValueError(f"unknown feature {spec!r}: components must be among {', '.join(valid)}")
    return components


def _resolve(name: str) -> tuple[FeatureSpec, ...]:
    if not isinstance(name, str):
        raise TypeError(f"feature name must be a str, got {type(name).__name__}")
    parts = tuple(part.strip() for part in name.split("+"))
    unknown = [part for part in parts if part not in _SPECS]
    if unknown:
        raise ValueError(
            f"unknown feature {unknown[0]!r} in {name!r}; valid names are "
            f"{', '.join(FEATURE_NAMES)}, or several joined by '+' (e.g. 'gray+cn')"
        )
    if len(set(parts)) != len(parts):
        raise ValueError(f"feature {name!r} names a feature more than once")
    specs = tuple(_SPECS[part] for part in parts)
    if len({spec.cell_size for spec in specs}) > 1:
        sizes = {spec.name: spec.cell_size for spec in specs}
        raise ValueError(f"features in {name!r} have different cell sizes {sizes}")
    return specs


def feature_dim(name: str) -> int:
    """Number of channels D of the feature ``name`` (single or ``+``-combined)."""
    return sum(spec.dim for spec in _resolve(name))


class FeatureExtractor:
    """Computes a named feature map from a frame.

    Parameters
    ----------
    name : str
        One of :data:`FEATURE_NAMES` or several joined by ``+``; ``"gray+cn"`` (D = 11) is the
        thesis's main configuration.
    color_names : ColorNameTable, optional
        Table used by ``"cn"``. Defaults to the embedded model
        (:meth:`ColorNameTable.embedded`), computed on first use and owned by this extractor;
        pass one table to share it between extractors.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the valid ones).

    Examples
    --------
    >>> extractor = FeatureExtractor("gray+cn")
    >>> extractor.dim
    11
    """

    def __init__(self, name: str, color_names: ColorNameTable | None = None) -> None:
        self._specs = _resolve(name)
        self.name = "+".join(spec.name for spec in self._specs)
        needs_cn = any(spec.name == "cn" for spec in self._specs)
        self._color_names = color_names
        if self._color_names is None and needs_cn:
            self._color_names = ColorNameTable.embedded()

    @property
    def dim(self) -> int:
        """Number of output channels D."""
        return sum(spec.dim for spec in self._specs)

    @property
    def needs_rgb(self) -> bool:
        """True if any part of the feature needs an RGB frame."""
        return any(spec.needs_rgb for spec in self._specs)

    @property
    def cell_size(self) -> int:
        """Pixels per output cell along each axis (1: one feature vector per pixel)."""
        return self._specs[0].cell_size

    @property
    def color_names(self) -> ColorNameTable | None:
        """The Color Names table in use, or None if the feature does not use one."""
        return self._color_names

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """Feature map of ``image``.

        Parameters
        ----------
        image : ndarray, uint8
            RGB ``(H, W, 3)``; grayscale ``(H, W)`` or ``(H, W, 1)`` only for ``"gray"``.

        Returns
        -------
        (H, W, dim) float32

        Raises
        ------
        TypeError
            If ``image`` is not a uint8 numpy array.
        ValueError
            If a colour feature is asked of a grayscale frame, or the shape is not a frame's.
        """
        if self.needs_rgb:
            cs.require_rgb(image, self.name)
        else:
            cs.require_image(image, self.name)
        maps = [spec.compute(image, self._color_names) for spec in self._specs]
        return maps[0] if len(maps) == 1 else np.concatenate(maps, axis=2)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, dim={self.dim})"
