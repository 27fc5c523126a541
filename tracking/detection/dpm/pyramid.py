"""The DPM feature pyramid of voc-release5 ``features/featpyramid.m``, computed level by level.

Level ``k`` (0-based; voc-release5 counts from 1) of the pyramid of an image holds HOG features
(:func:`tracking.features.hog.fhog`) of the image resized by ``factor_k`` with cells of
``hog_cell_k`` pixels, so a cell covers ``hog_cell_k / factor_k`` image pixels. With
``E = interval`` when the model has the extra octave (``features.extra_octave``) and ``E = 0``
otherwise, and ``sc = 2^(1 / interval)``:

* ``k < E``: ``sbin / 4`` cells on the image scaled by ``sc^-k`` (roots never sit here; these
  levels carry the parts of roots on ``sbin / 2`` cells);
* ``E <= k < E + interval``: ``sbin / 2`` cells on the image scaled by ``sc^-(k - E)``;
* ``k >= E + interval``: ``sbin`` cells on the image scaled by ``sc^-(k - E - interval)``,
  down to the scale where the image's short side is 5 cells (``max_scale`` of featpyramid.m).

So level ``k - interval`` has exactly twice the resolution of level ``k``: the parts of a root
on level ``k`` sit there. Every level is padded by ``(pad_y + 1, pad_x + 1)`` cells of zeros
(``pad = model.maxsize``; the 1 replaces the border ring that HOG drops), and the truncation
channel (the 32nd) is 1 in the padding, 0 inside (featpyramid.m).

As featpyramid.m, the first octave's images are resized from the input and every image an
octave below one already made is that image halved (cheaper than resizing the whole input for
every level). Differences from featpyramid.m, all documented approximations: images are resized
with OpenCV (``INTER_AREA`` when shrinking, ``INTER_LINEAR`` when enlarging) in float32 instead
of voc-release5's ``resize.cc``, and an optional ``upscale`` enlarges the input first (to find
people smaller than the model's smallest root). Only the levels asked for are computed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from tracking.features.hog import fhog_cells

__all__ = ["PyramidLevel", "level_chains", "level_features", "pyramid_levels"]


@dataclass(frozen=True, slots=True)
class PyramidLevel:
    """Where one pyramid level comes from.

    Attributes
    ----------
    index:
        0-based voc-release5 level index ``k`` (``loc_feat.m`` and the part offset use it).
    factor:
        Resize factor applied to the input image (including any upscale).
    hog_cell:
        HOG cell size in pixels of the resized image (``sbin / 4``, ``sbin / 2`` or ``sbin``).
    interval:
        Levels per octave of the pyramid.
    """

    index: int
    factor: float
    hog_cell: int
    interval: int

    @property
    def cell(self) -> float:
        """Cell size in input-image pixels: ``hog_cell / factor``."""
        return self.hog_cell / self.factor

    @property
    def octave(self) -> int:
        """Row of ``loc_feat.m``: 0, 1 for the first two octaves of levels, 2 above."""
        return min(self.index // self.interval, 2)


def _c_round(value: float) -> int:
    return math.floor(value + 0.5)


def pyramid_levels(
    image_shape: tuple[int, ...],
    sbin: int,
    interval: int,
    extra_octave: bool,
    upscale: float = 1.0,
) -> tuple[PyramidLevel, ...]:
    """All levels of the pyramid of an image, as voc-release5 ``featpyramid.m`` lays them out.

    Parameters
    ----------
    image_shape:
        ``(H, W, ...)`` of the input image.
    sbin:
        The model's cell size (8).
    interval:
        Levels per octave (``model.interval``, 10).
    extra_octave:
        ``model.features.extra_octave``.
    upscale:
        Enlarge the input by this factor before building the pyramid (1: voc-release5).

    Returns
    -------
    tuple of PyramidLevel
        Ordered by index: finest cells first.
    """
    if interval < 1:
        raise ValueError(f"interval must be a positive int, got {interval}")
    if not (np.isfinite(upscale) and upscale > 0):
        raise ValueError(f"upscale must be a positive number, got {upscale}")
    extra = interval if extra_octave else 0
    short_side = min(image_shape[0], image_shape[1]) * upscale
    ratio = short_side / (5 * sbin)
    max_scale = 1 + math.floor(math.log(ratio) / math.log(2 ** (1 / interval))) if ratio > 0 else 0
    count = extra + interval + max(max_scale, interval)
    levels = []
    for k in range(count):
        if k < extra:
            cell, i = sbin // 4, k
        elif k < extra + interval:
            cell, i = sbin // 2, k - extra
        else:
            cell, i = sbin, k - extra - interval
        levels.append(PyramidLevel(k, upscale * 2.0 ** (-i / interval), cell, interval))
    return tuple(levels)


def resize_image(image: np.ndarray, factor: float) -> np.ndarray:
    """``image`` (uint8 or float) scaled by ``factor`` as float32, ``round(size * factor)``."""
    source = image.astype(np.float32, copy=False)
    if factor == 1.0:
        return source
    height, width = image.shape[:2]
    size = (max(1, _c_round(width * factor)), max(1, _c_round(height * factor)))
    interpolation = cv2.INTER_AREA if factor < 1.0 else cv2.INTER_LINEAR
    return cv2.resize(source, size, interpolation=interpolation)


def level_chains(levels: tuple[PyramidLevel, ...] | list[PyramidLevel]) -> list[list[PyramidLevel]]:
    """``levels`` grouped by halving chain: resize factors a power of two apart, largest first.

    Level ``k``'s factor is ``upscale * 2^(-i / interval)`` with ``i = k``, ``k - interval`` or
    ``k - 2 interval`` (:func:`pyramid_levels`), so two levels' factors are a power of two
    apart exactly when their indices agree modulo ``interval`` (an integer test: a key rounded
    from the factor can split a chain at a rounding boundary). :func:`level_features` makes
    each chain's images from one resize of the input, so a chain is the unit to compute on one
    thread.
    """
    chains: dict[int, list[PyramidLevel]] = {}
    for level in sorted(levels, key=lambda lv: -lv.factor):
        chains.setdefault(level.index % level.interval, []).append(level)
    return list(chains.values())


def level_features(
    image: np.ndarray,
    levels: tuple[PyramidLevel, ...] | list[PyramidLevel],
    pad: tuple[int, int],
) -> dict[int, np.ndarray]:
    """Padded HOG features of the requested levels of ``image``'s pyramid.

    Levels with the same resize factor share one resized image; an image whose factor is half
    that of one already made is that image halved (featpyramid.m's octaves).

    Parameters
    ----------
    image:
        ``(H, W, 3)`` RGB or ``(H, W)`` image, values in 0..255, finite: the caller checks
        it (:class:`.detector.DpmDetector` checks each frame once, not every resized image).
    levels:
        The levels to compute (from :func:`pyramid_levels`).
    pad:
        ``(pad_y, pad_x)`` in cells (``model.maxsize``): each map has ``pad + 1`` cells of
        zeros on every side, with the truncation channel 1 there (featpyramid.m).

    Returns
    -------
    dict
        Level index -> ``(h + 2 pad_y + 2, w + 2 pad_x + 2, 32)`` float32 padded features.
    """
    source = image.astype(np.float32, copy=False)
    out: dict[int, np.ndarray] = {}
    for chain in level_chains(levels):
        by_factor: dict[float, list[PyramidLevel]] = {}
        for level in chain:  # equal factors are equal floats: the same expression of k
            by_factor.setdefault(level.factor, []).append(level)
        parent: tuple[float, np.ndarray] | None = None
        for group in by_factor.values():  # largest factor first
            factor = group[0].factor
            # the image above is the parent unless levels between them were not asked for
            if parent is not None and math.isclose(parent[0], 2 * factor, rel_tol=1e-9):
                scaled = resize_image(parent[1], 0.5)
            else:
                scaled = resize_image(source, factor)
            parent = (factor, scaled)
            # one pass over the pixels for every cell size of this image
            maps = fhog_cells(
                scaled,
                [lv.hog_cell for lv in group],
                truncation_feature=True,
                margin=(pad[0] + 1, pad[1] + 1),
                checked=True,  # resized from a checked image
            )
            for level, features in zip(group, maps, strict=True):
                out[level.index] = features
    return out
