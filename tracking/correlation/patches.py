"""Sampling image patches around a target, with the border replicated outside the frame."""

from __future__ import annotations

import cv2
import numpy as np


def extract_patch(
    frame: np.ndarray,
    center: tuple[float, float],
    size: tuple[float, float],
    out_size: tuple[int, int],
) -> np.ndarray:
    """The ``size``-sized window of ``frame`` centred at ``center``, resampled to ``out_size``.

    Parameters
    ----------
    frame:
        ``(H, W)`` or ``(H, W, C)`` image.
    center:
        ``(cx, cy)`` in pixels.
    size:
        ``(w, h)`` of the window in pixels (may be fractional; rounded, at least 1).
    out_size:
        ``(w, h)`` of the returned patch.

    Returns
    -------
    ndarray
        ``(out_h, out_w[, C])``, same dtype as ``frame``. Pixels outside the frame repeat its
        nearest border pixel, which keeps the periodic extension of the patch free of the
        artificial edges a constant fill would add.
    """
    width = max(round(size[0]), 1)
    height = max(round(size[1]), 1)
    left = int(np.floor(center[0] - width / 2.0 + 0.5))
    top = int(np.floor(center[1] - height / 2.0 + 0.5))
    rows = np.clip(np.arange(top, top + height), 0, frame.shape[0] - 1)
    cols = np.clip(np.arange(left, left + width), 0, frame.shape[1] - 1)
    inside = rows[0] == top and rows[-1] == top + height - 1
    inside = inside and cols[0] == left and cols[-1] == left + width - 1
    # A plain slice is a view; fancy indexing (only needed at the border) copies.
    patch = frame[top : top + height, left : left + width] if inside else frame[np.ix_(rows, cols)]
    if (width, height) != tuple(out_size):
        shrinking = width * height > out_size[0] * out_size[1]
        interpolation = cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR
        patch = cv2.resize(
            np.ascontiguousarray(patch), tuple(out_size), interpolation=interpolation
        )
    return patch


def zoom_about_centre(grid: np.ndarray, factor: float) -> np.ndarray:
    """``grid`` ``(M, N[, D])`` as a sample ``factor`` times as large would see it: output cell
    ``i`` reads the input at ``factor`` times its offset from the centre (cell centres at
    ``i + 1/2``), bilinearly; beyond the edges the edge cells repeat, as in
    :func:`extract_patch`."""
    rows, cols = grid.shape[:2]
    affine = np.array(
        [
            [factor, 0.0, (cols / 2.0 - 0.5) * (1.0 - factor)],
            [0.0, factor, (rows / 2.0 - 0.5) * (1.0 - factor)],
        ]
    )
    flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
    border = cv2.BORDER_REPLICATE
    zoomed = cv2.warpAffine(grid, affine, (cols, rows), flags=flags, borderMode=border)
    return zoomed.reshape(grid.shape)
