"""Felzenszwalb HOG features (Felzenszwalb et al., PAMI 2010, §6), as voc-release5 computes them.

The 31 features of a cell are, in order (§6.2 and voc-release5 ``features/features.cc``):

* ``0..17``  contrast-sensitive orientations: bin ``o`` is the direction ``o * 20°`` of the
  gradient, measured from the +x (column, rightwards) axis towards +y (row, downwards);
* ``18..26`` contrast-insensitive orientations: bin ``18 + o`` pools ``o`` and ``o + 9``
  (``o * 20°`` modulo 180°);
* ``27..30`` texture (gradient energy) features: ``0.2357`` times the sum of the 18
  contrast-sensitive values under each of the four block normalisations;
* ``31`` (only with ``truncation_feature=True``) the voc-release5 "truncation" channel, always 0
  here; the DPM feature pyramid sets it to 1 in its padding cells.

Each cell histogram is normalised by the energy of each of the four 2x2 cell blocks that contain
it, clipped at 0.2 and the four results summed with weight 0.5 (the analytic projection of the
36-dimensional Dalal-Triggs vector, §6.3).

The computation follows voc-release5 step for step, vectorised:

1. ``cells = round(H / sbin), round(W / sbin)`` (C ``round``: halves away from zero); only the
   pixels ``1 .. cells * sbin - 2`` of each axis are visited, with image coordinates clamped to
   ``H - 2`` / ``W - 2`` (so the image is cropped or its last interior row/column repeated);
2. centred differences per colour channel; the channel with the largest squared magnitude wins
   (ties to the first channel);
3. the orientation is the first maximum of ``±(uu[o] dx + vv[o] dy)`` over the 18 directions in
   the order ``+0, -0, +1, -1, ...`` with the 4-decimal ``uu``/``vv`` tables of ``features.cc``;
4. the magnitude is shared bilinearly between the four nearest cell centres;
5. normalisation, truncation at 0.2 and the texture features as above; the outermost ring of
   cells is dropped, so the output is ``max(cells - 2, 0)`` cells along each axis.

voc-release5 stores histograms and features in single precision; so does this module. It also
takes the gradients in single precision (voc-release5: double). That is exact for 8-bit images
(every orientation decision agrees with double precision for integer gradients up to +-510);
for other float images the features agree to ~1e-7.
"""

from __future__ import annotations

import numpy as np

__all__ = ["NUM_FEATURES", "fhog", "hog_feature_map"]

# Unit vectors of the 9 directions o * 20° (features.cc: uu = cos, vv = sin, 4 decimals).
_UU = np.array(
    [1.0000, 0.9397, 0.7660, 0.500, 0.1736, -0.1736, -0.5000, -0.7660, -0.9397], dtype=np.float32
)
_VV = np.array(
    [0.0000, 0.3420, 0.6428, 0.8660, 0.9848, 0.9848, 0.8660, 0.6428, 0.3420], dtype=np.float32
)
_NUM_ORIENTATIONS = 18
_EPS = 1e-4  # features.cc: keeps the block normalisation finite on flat images
_CLIP = np.float32(0.2)  # truncation of each normalised value (§6.2)
_TEXTURE_WEIGHT = np.float32(0.2357)  # ~ 1 / sqrt(18)

_STRIP_PIXELS = 32768  # visited pixels per strip of _histograms (keeps temporaries in cache)

NUM_FEATURES = 31
"""Features per cell without the truncation channel (18 + 9 + 4)."""


def _c_round_div(n: int, d: int) -> int:
    """``round(n / d)`` for non-negative ints with C's rounding (halves up, unlike ``round``)."""
    return (2 * n + d) // (2 * d)


def _check_cell_size(cell_size: object) -> int:
    """The cell size as a positive int, or ValueError."""
    if isinstance(cell_size, bool) or not isinstance(cell_size, int | np.integer):
        raise ValueError(f"cell_size must be a positive int, got {cell_size!r}")
    if cell_size < 1:
        raise ValueError(f"cell_size must be a positive int, got {cell_size}")
    return int(cell_size)


def _validated(image: np.ndarray) -> np.ndarray:
    """``image`` as an array of shape ``(H, W)`` or ``(H, W, 3)`` with finite real values."""
    image = np.asarray(image)
    if image.dtype == np.bool_ or not (
        np.issubdtype(image.dtype, np.integer) or np.issubdtype(image.dtype, np.floating)
    ):
        raise ValueError(f"image must have an integer or floating dtype, got {image.dtype}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {image.shape}")
    # min and max propagate NaN and show infinities, without a boolean copy of the image.
    if (
        image.size
        and np.issubdtype(image.dtype, np.floating)
        and not (np.isfinite(image.min()) and np.isfinite(image.max()))
    ):
        raise ValueError("image must contain only finite values")
    return image


def _select(mask: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.where(mask, a, b)`` for float32 arrays, exact and branch-free (on the bit patterns).

    ``np.where`` branches on every element and is ~30x slower on the random masks met here.
    """
    bits_a, bits_b = a.view(np.uint32), b.view(np.uint32)
    ones = np.negative(mask, dtype=np.uint32)  # True -> 0xFFFFFFFF, False -> 0
    return (bits_b ^ ((bits_a ^ bits_b) & ones)).view(np.float32)


def _gradients(image: np.ndarray, rows: slice, n_cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Orientation bin and magnitude of the strongest-channel gradient (features.cc).

    Covers the pixels ``y = rows.start + 1 .. rows.stop``, ``x = 1 .. n_cols`` of ``image``
    (``(H, W)`` or ``(H, W, 3)``), which must be interior (``rows.stop <= H - 2``,
    ``n_cols <= W - 2``). Returns the orientation bin (uint8, 0..17) and
    ``sqrt(dx^2 + dy^2)`` (float32), both ``(rows.stop - rows.start, n_cols)``.
    """
    window = image[rows.start : rows.stop + 2, : n_cols + 2]
    planes = window[np.newaxis] if window.ndim == 2 else np.moveaxis(window, 2, 0)
    planes = np.ascontiguousarray(planes, dtype=np.float32)  # (C, rows + 2, n_cols + 2)
    dy = planes[:, 2:, 1:-1] - planes[:, :-2, 1:-1]  # centred differences
    dx = planes[:, 1:-1, 2:] - planes[:, 1:-1, :-2]
    energy = dx * dx + dy * dy  # v = dx^2 + dy^2 per channel
    gx, gy, v = dx[0], dy[0], energy[0]
    for c in range(1, planes.shape[0]):  # "pick channel with strongest gradient" (strict >)
        better = energy[c] > v
        gx = _select(better, dx[c], gx)
        gy = _select(better, dy[c], gy)
        v = np.maximum(v, energy[c])

    # Snap to 18 orientations: the first o maximising |uu[o] dx + vv[o] dy|, then o if that dot
    # is positive, o + 9 if negative. This is features.cc's "if (dot > best) ... else if
    # (-dot > best)" chain: a strictly larger |dot| can only pass one of its two branches.
    # The bin is updated arithmetically (bin += better * (new - bin), wrapping uint8), which
    # is exact and, unlike a masked assignment, does not branch per pixel.
    best = np.zeros_like(gx)
    orient = np.zeros(gx.shape, dtype=np.uint8)
    dot = np.empty_like(gx)
    mag = np.empty_like(gx)
    better = np.empty(gx.shape, dtype=np.bool_)
    candidate = np.empty_like(orient)
    for o in range(9):
        np.multiply(gx, _UU[o], out=dot)
        np.multiply(gy, _VV[o], out=mag)
        dot += mag  # uu[o] dx + vv[o] dy
        np.abs(dot, out=mag)
        np.greater(mag, best, out=better)
        np.maximum(best, mag, out=best)
        np.less(dot, 0, out=candidate.view(np.bool_))
        candidate *= 9
        candidate += o  # o, or o + 9 for a negative dot
        candidate -= orient
        candidate *= better
        orient += candidate
    np.sqrt(v, out=mag)
    return orient, mag


def _bilinear_weights(n_pixels: int, sbin: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell index and weight of the pixels ``1 .. n_pixels`` along one axis (features.cc).

    ``xp = (x + 0.5) / sbin - 0.5``; the pixel gives ``1 - frac(xp)`` to cell ``floor(xp)`` and
    ``frac(xp)`` to the next. The returned index is ``floor(xp) + 1``, i.e. into a cell array
    padded by one cell on each side (cells outside ``0 .. cells - 1`` are later dropped, as the
    bounds checks of features.cc drop them).
    """
    xp = (np.arange(1, n_pixels + 1, dtype=np.float64) + 0.5) / sbin - 0.5
    ixp = np.floor(xp)
    return (ixp + 1).astype(np.int64), xp - ixp


def _histograms(image: np.ndarray, sbin: int, cells: tuple[int, int]) -> np.ndarray:
    """Soft-binned orientation histograms, ``(cells_y, cells_x, 18)`` float32 (§6.1).

    features.cc visits ``y = 1 .. cells_y * sbin - 2`` (likewise x) and reads the image at
    ``min(y, H - 2)``: the gradient is computed on the interior rows and columns that exist
    and the last one is repeated for the clamped rest.

    The work is done in strips of whole cell rows so that the temporaries stay in the cache
    (about 2x faster than whole-image arrays on a 768x576 image).
    """
    height, width = image.shape[:2]
    n_rows, n_cols = cells[0] * sbin - 2, cells[1] * sbin - 2  # visited pixels per axis
    rows_in, cols_in = min(n_rows, height - 2), min(n_cols, width - 2)  # of which interior
    cy, wy = _bilinear_weights(n_rows, sbin)
    cx, wx = _bilinear_weights(n_cols, sbin)
    wx = wx.astype(np.float32)
    padded = (cells[0] + 2, cells[1] + 2, _NUM_ORIENTATIONS)
    hist = np.zeros(padded, dtype=np.float64)

    strip = sbin * max(1, _STRIP_PIXELS // (sbin * n_cols))
    for start in range(0, rows_in, strip):
        stop = min(start + strip, rows_in)
        orient, mag = _gradients(image, slice(start, stop), cols_in)
        end = n_rows if stop == rows_in else stop  # the last strip takes the clamped rows
        if end > stop or n_cols > cols_in:  # clamped coordinates repeat the last row/column
            pad = ((0, end - stop), (0, n_cols - cols_in))
            orient, mag = np.pad(orient, pad, mode="edge"), np.pad(mag, pad, mode="edge")
        n = end - start

        # Along x, by bincount into (row, padded cell, orientation): the near cell gets
        # (1 - wx) m, the far cell (index + 1) wx m; same index, the second shifted by a cell.
        index = orient + _NUM_ORIENTATIONS * (cx + padded[1] * np.arange(n)[:, np.newaxis])
        size = n * padded[1] * _NUM_ORIENTATIONS
        far = mag * wx
        by_row = np.bincount(index.ravel(), (mag - far).ravel(), minlength=size)
        far = np.bincount(index.ravel(), far.ravel(), minlength=size)
        by_row = by_row.reshape(n, *padded[1:])
        by_row[:, 1:] += far.reshape(n, *padded[1:])[:, :-1]

        # Along y: rows y = 1 + offset + k sbin (k = 0, 1, ...) fall in consecutive cells, so
        # each residue class is one strided slice added to two shifted slices of hist.
        for offset in range(min(sbin, n)):
            rows = slice(offset, n, sbin)
            first = cy[start + offset]
            count = len(range(offset, n, sbin))
            weight = wy[start:end][rows, np.newaxis, np.newaxis]
            hist[first : first + count] += (1.0 - weight) * by_row[rows]
            hist[first + 1 : first + count + 1] += weight * by_row[rows]
    return hist[1:-1, 1:-1].astype(np.float32)


def fhog(image: np.ndarray, cell_size: int = 8, *, truncation_feature: bool = False) -> np.ndarray:
    """Felzenszwalb HOG features of an image, as voc-release5 ``features(im, sbin)`` computes.

    Parameters
    ----------
    image:
        ``(H, W, 3)`` RGB or ``(H, W)`` grayscale (treated as three equal channels), integer
        or floating. Values are used as they are, without rescaling: voc-release5 takes a
        ``double`` image in 0..255, so pass ``uint8`` images or floats in 0..255 to match its
        features exactly (the features are nearly invariant to the scale of the values,
        except for the ``eps = 1e-4`` in the normalisation).
    cell_size:
        Cell side ``sbin`` in pixels (8 for the DPM models; 4 in trackers).
    truncation_feature:
        Append voc-release5's 32nd channel (all zeros) so the map can be correlated with
        voc-release5 model filters (32 channels, ``model.features.truncation_dim = 32``).

    Returns
    -------
    np.ndarray
        float32 ``(max(round(H / s) - 2, 0), max(round(W / s) - 2, 0), 31 or 32)``, ``s`` the
        cell size, ``round`` rounding halves up. Cell ``(i, j)`` of the map is centred on pixel
        ``((i + 1.5) s - 0.5, (j + 1.5) s - 0.5)``. An image smaller than 2.5 cells along an
        axis yields an empty map (zero cells along that axis), not an error.

    Raises
    ------
    ValueError
        On a wrong shape, dtype, non-finite value or a cell size that is not a positive int.

    References
    ----------
    P. F. Felzenszwalb, R. B. Girshick, D. McAllester, D. Ramanan, "Object Detection with
    Discriminatively Trained Part-Based Models", IEEE TPAMI 32(9), 2010, §6; voc-release5
    ``features/features.cc``.
    """
    return _fhog(_validated(image), _check_cell_size(cell_size), truncation_feature)


def _fhog(image: np.ndarray, sbin: int, truncation_feature: bool) -> np.ndarray:
    """:func:`fhog` of a validated image."""
    height, width = image.shape[:2]
    cells = (_c_round_div(height, sbin), _c_round_div(width, sbin))
    out_shape = (max(cells[0] - 2, 0), max(cells[1] - 2, 0))
    n_features = NUM_FEATURES + int(truncation_feature)
    feat = np.zeros((*out_shape, n_features), dtype=np.float32)
    if 0 in out_shape:  # nothing survives the dropped border ring (and H, W may be < 3)
        return feat

    hist = _histograms(image, sbin, cells)  # (cells_y, cells_x, 18)

    # Block energies: norm = sum_o (h[o] + h[o + 9])^2 per cell, summed over each 2x2 block.
    insensitive = hist[..., :9] + hist[..., 9:]
    norm = np.einsum("ijk,ijk->ij", insensitive, insensitive)
    block = norm[:-1, :-1] + norm[1:, :-1] + norm[:-1, 1:] + norm[1:, 1:]
    inv = (1.0 / np.sqrt(block.astype(np.float64) + _EPS)).astype(np.float32)
    # The four blocks holding cell (i + 1, j + 1): block index offsets (1,1), (0,1), (1,0), (0,0)
    # are n1..n4 of features.cc (the order of the texture features).
    oh, ow = out_shape
    norms = [inv[1 : oh + 1, 1 : ow + 1], inv[:oh, 1 : ow + 1], inv[1 : oh + 1, :ow], inv[:oh, :ow]]
    centre = hist[1:-1, 1:-1]
    centre_insensitive = insensitive[1:-1, 1:-1]
    for k, n in enumerate(norms):
        n = n[..., np.newaxis]
        sensitive = np.minimum(centre * n, _CLIP)  # h_k = min(h * n_k, 0.2)
        feat[..., :18] += sensitive
        feat[..., 18:27] += np.minimum(centre_insensitive * n, _CLIP)
        feat[..., 27 + k] = _TEXTURE_WEIGHT * sensitive.sum(axis=-1)  # 0.2357 * t_k
    feat[..., :27] *= np.float32(0.5)  # 0.5 * (h1 + h2 + h3 + h4)
    return feat


def hog_feature_map(image: np.ndarray, cell_size: int = 4) -> np.ndarray:
    """HOG map covering a whole patch, for correlation-filter trackers.

    :func:`fhog` drops the outer ring of cells. Here the patch is first padded by ``cell_size``
    pixels of edge replication on every side, so the map has one cell per ``s x s`` block of the
    patch: cell ``(i, j)`` is centred on the block of rows ``i * s .. (i + 1) * s - 1`` and
    columns ``j * s .. (j + 1) * s - 1`` (its bilinear support reaches half a cell beyond).
    Gradients in the border cells see the replicated edge, i.e. none across the patch border.

    Parameters
    ----------
    image:
        ``(H, W, 3)`` or ``(H, W)`` patch, as for :func:`fhog`.
    cell_size:
        Cell side ``s`` in pixels.

    Returns
    -------
    np.ndarray
        float32 ``(round(H / s), round(W / s), 31)`` (``round`` halves up; ``H // s`` by
        ``W // s`` when the patch is a whole number of cells).
    """
    sbin = _check_cell_size(cell_size)
    image = _validated(image)
    height, width = image.shape[:2]
    if height == 0 or width == 0:  # nothing to replicate
        shape = (_c_round_div(height, sbin), _c_round_div(width, sbin), NUM_FEATURES)
        return np.zeros(shape, dtype=np.float32)
    pad = ((sbin, sbin), (sbin, sbin)) + ((0, 0),) * (image.ndim - 2)
    return _fhog(np.pad(image, pad, mode="edge"), sbin, truncation_feature=False)
