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
   the order ``+0, -0, +1, -1, ...`` with the 4-decimal ``uu``/``vv`` tables of ``features.cc``
   (for 8-bit images the bin of each of the 511 x 511 possible gradients is computed once, in
   the same way, and looked up);
4. the magnitude is shared bilinearly between the four nearest cell centres;
5. normalisation, truncation at 0.2 and the texture features as above; the outermost ring of
   cells is dropped, so the output is ``max(cells - 2, 0)`` cells along each axis.

voc-release5 stores histograms and features in single precision; so does this module. It also
takes the gradients in single precision (voc-release5: double). That is exact for 8-bit images
(every orientation decision agrees with double precision for integer gradients up to +-510);
for other float images the features agree to ~1e-7.
"""

from __future__ import annotations

import functools

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

# Visited pixels per strip of _histograms (keeps temporaries in cache); images with no more
# are done in a single pass.
_STRIP_PIXELS = 32768

_MAX_BYTE_GRADIENT = 255  # centred differences of 8-bit values lie in -255..255
_BYTE_CODE_SCALE = 2 * _MAX_BYTE_GRADIENT + 1  # (dx, dy) -> 511 dx + dy: distinct codes

# np.minimum against an array is vectorised, against a scalar it is not (~5x slower).
_CLIP_BLOCK = np.full(1 << 16, _CLIP, dtype=np.float32)
_CLIP_BLOCK.flags.writeable = False
# Cells per band of the block normalisation: its 27 values per cell fit one _CLIP_BLOCK.
_NORM_BAND_CELLS = _CLIP_BLOCK.size // 27

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


def _orientations(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Orientation bin (uint8, 0..17) of the float32 gradients ``(gx, gy)`` (features.cc).

    Snap to 18 orientations: the first o maximising |uu[o] dx + vv[o] dy|, then o if that dot
    is positive, o + 9 if negative. This is features.cc's "if (dot > best) ... else if
    (-dot > best)" chain: a strictly larger |dot| can only pass one of its two branches.
    The bin is updated arithmetically (bin += better * (new - bin), wrapping uint8), which
    is exact and, unlike a masked assignment, does not branch per pixel.
    """
    best = np.zeros_like(gx)
    orient = np.zeros(gx.shape, dtype=np.uint8)
    dot = np.empty_like(gx)
    absolute = np.empty_like(gx)
    better = np.empty(gx.shape, dtype=np.bool_)
    candidate = np.empty_like(orient)
    for o in range(9):
        np.multiply(gx, _UU[o], out=dot)
        np.multiply(gy, _VV[o], out=absolute)
        dot += absolute  # uu[o] dx + vv[o] dy
        np.abs(dot, out=absolute)
        np.greater(absolute, best, out=better)
        np.maximum(best, absolute, out=best)
        np.less(dot, 0, out=candidate.view(np.bool_))
        candidate *= 9
        candidate += o  # o, or o + 9 for a negative dot
        candidate -= orient
        candidate *= better
        orient += candidate
    return orient


@functools.cache
def _orientation_table() -> np.ndarray:
    """:func:`_orientations` of every integer gradient ``-255 <= dx, dy <= 255`` (read-only).

    Entry ``511 dx + dy`` (a negative code counts from the end, as numpy indexes) holds the
    bin of ``(dx, dy)``: the codes of the 511 x 511 gradients are distinct and fill the table.
    """
    span = np.arange(-_MAX_BYTE_GRADIENT, _MAX_BYTE_GRADIENT + 1)
    dx, dy = np.repeat(span, span.size), np.tile(span, span.size)
    table = np.empty(span.size * span.size, dtype=np.uint8)
    table[_BYTE_CODE_SCALE * dx + dy] = _orientations(dx.astype(np.float32), dy.astype(np.float32))
    table.flags.writeable = False
    return table


@functools.lru_cache(maxsize=16)
def _channel_rank(size: int) -> tuple[np.ndarray, np.ndarray]:
    """For ``size`` interleaved RGB values: ``2 - c`` of each, and ``3 i + 2`` of pixel i.

    Both int32 and read-only; see :func:`_byte_gradients`.
    """
    rank = np.tile(np.array([2, 1, 0], dtype=np.int32), size // 3)
    last = np.arange(2, size, 3, dtype=np.int32)
    rank.flags.writeable = last.flags.writeable = False
    return rank, last


def _planes(
    image: np.ndarray, pad: int, n_rows: int, n_cols: int, dtype: type[np.generic]
) -> np.ndarray:
    """Rows ``0 .. n_rows - 1`` and columns ``0 .. n_cols - 1`` of ``image`` edge-padded by
    ``pad`` pixels on every side, as a contiguous ``(n_rows, n_cols, C)`` ``dtype`` array.

    The window must not extend beyond the padded image.
    """
    height, width = image.shape[:2]
    planes = np.empty((n_rows, n_cols, 1 if image.ndim == 2 else 3), dtype=dtype)
    rows, cols = min(height, n_rows - pad), min(width, n_cols - pad)  # of the image itself
    bottom, right = pad + rows, pad + cols
    source = image[:rows, :cols].reshape(rows, cols, -1)
    planes[pad:bottom, pad:right] = source
    if pad:  # replicate the first/last column, then the first/last row (corners included)
        planes[pad:bottom, :pad] = source[:, :1]
        planes[pad:bottom, right:] = source[:, -1:]
        planes[:pad] = planes[pad]
        planes[bottom:] = planes[bottom - 1]
    return planes


def _gradients(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orientation bin and magnitude of the strongest-channel gradient (features.cc).

    ``planes`` is ``(rows + 2, cols + 2, C)``, C = 1 or 3, int32 (an 8-bit image) or float32.
    Returns the orientation bin (uint8, 0..17) and ``sqrt(dx^2 + dy^2)`` (float32) of the
    pixels ``1 .. rows`` by ``0 .. cols + 1``: columns 1 .. cols are the interior pixels, the
    first and the last column are junk (finite, computed across the row ends).

    The centred differences are taken on the flattened array, so every step is one
    contiguous pass.
    """
    flat = planes.reshape(-1)
    step, row = planes.shape[2], planes.shape[1] * planes.shape[2]
    n = flat.size - 2 * row
    dx = flat[row + step : row + step + n] - flat[row - step : row - step + n]
    dy = flat[2 * row :] - flat[:n]
    if planes.dtype == np.int32:
        orient, mag = _byte_gradients(dx, dy, step)
    else:
        orient, mag = _float_gradients(dx, dy, step)
    return orient.reshape(-1, planes.shape[1]), mag.reshape(-1, planes.shape[1])


def _float_gradients(dx: np.ndarray, dy: np.ndarray, step: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_gradients` from float32 centred differences, ``step`` channels interleaved."""
    energy = dx * dx + dy * dy  # v = dx^2 + dy^2 per channel
    gx, gy, v = dx[::step], dy[::step], energy[::step]
    for c in range(1, step):  # "pick channel with strongest gradient" (strict >)
        better = energy[c::step] > v
        gx = _select(better, dx[c::step], gx)
        gy = _select(better, dy[c::step], gy)
        v = np.maximum(v, energy[c::step])
    return _orientations(gx, gy), np.sqrt(v)


def _byte_gradients(dx: np.ndarray, dy: np.ndarray, step: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_gradients` from the int32 centred differences of an 8-bit image.

    They are integers in -255..255, so the bin of the winning channel is read from
    :func:`_orientation_table` (which holds the float32 computation of every such gradient)
    and the magnitude is ``sqrt`` of the exact integer energy. The strongest channel is the
    maximum of ``4 (dx^2 + dy^2) + 2 - c``: ties go to the first channel, as features.cc's
    strict ``>`` gives them.
    """
    code = dx * _BYTE_CODE_SCALE
    code += dy  # the table entry of (dx, dy)
    energy = np.multiply(dx, dx, out=dx)
    energy += np.multiply(dy, dy, out=dy)  # dx^2 + dy^2 <= 130050
    if step == 3:
        rank, last = _channel_rank(energy.size)
        energy <<= 2
        energy += rank
        key = np.maximum(energy[0::3], energy[1::3])
        np.maximum(key, energy[2::3], out=key)
        winner = np.bitwise_and(key, 3)  # 2 - c
        np.subtract(last, winner, out=winner)  # 3 i + c: the winner's entry in code
        code = code.take(winner)
        energy = np.right_shift(key, 2, out=key)
    return _orientation_table().take(code), np.sqrt(energy, dtype=np.float32)


def _plane_dtype(image: np.ndarray) -> type[np.generic]:
    """int32 planes (table look-up) for 8-bit images, float32 planes for the others."""
    return np.int32 if image.dtype == np.uint8 else np.float32


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


@functools.lru_cache(maxsize=16)
def _single_pass_layout(
    sbin: int, cells: tuple[int, int], interior: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Histogram index and bilinear weights of the gradients, for :func:`_histograms`.

    The gradients come as :func:`_gradients` gives them for ``interior`` visited rows and
    columns: ``interior[0]`` rows of ``interior[1] + 2`` values, the first and last junk.
    Returns, read-only:

    * ``index``: ``(4, pixels)`` int64, the flat index of orientation 0 of the pixel's four
      cells in the ``(cells_y + 2, cells_x + 2, 18)`` padded histogram: the upper-left one,
      the one to its right, the one below and the diagonal one;
    * ``weights``: ``(4, pixels)`` float64, the pixel's bilinear share of each of them;
    * ``source``: None when the visited pixels are the interior ones, index and weights then
      cover the gradients in their order (the junk with weight 0); otherwise the visited
      pixels extend beyond the interior (features.cc clamps their coordinates), index and
      weights cover the visited pixels and ``source`` is the flat index of the gradient each
      one takes.
    """
    n_rows, n_cols = cells[0] * sbin - 2, cells[1] * sbin - 2
    cy, wy = _bilinear_weights(n_rows, sbin)
    cx, wx = _bilinear_weights(n_cols, sbin)
    if interior == (n_rows, n_cols):  # add the junk columns
        cx, wx = np.pad(cx, 1), np.pad(wx, 1)
        vx = np.pad(1.0 - wx[1:-1], 1)
        source = None
    else:
        vx = 1.0 - wx
        rows = np.minimum(np.arange(n_rows), interior[0] - 1)
        cols = np.minimum(np.arange(n_cols), interior[1] - 1) + 1
        source = (rows[:, np.newaxis] * (interior[1] + 2) + cols).ravel()
        source.flags.writeable = False
    index = (cy[:, np.newaxis] * (cells[1] + 2) + cx).ravel()
    # The upper-left cell, the one to its right, the one below, the diagonal one.
    neighbours = np.array([0, 1, cells[1] + 2, cells[1] + 3])[:, np.newaxis]
    index = _NUM_ORIENTATIONS * (index + neighbours)  # (4, pixels)
    wy, vy = wy[:, np.newaxis], 1.0 - wy[:, np.newaxis]
    weights = np.stack([vy * vx, vy * wx, wy * vx, wy * wx]).reshape(4, -1)
    index.flags.writeable = weights.flags.writeable = False
    return index, weights, source


def _histograms(image: np.ndarray, sbin: int, cells: tuple[int, int], pad: int) -> np.ndarray:
    """Soft-binned orientation histograms (§6.1) of ``image`` edge-padded by ``pad`` pixels on
    every side: float64 ``(cells_y + 2, cells_x + 2, 18)``, a ring of cells outside the image
    (which collects the weights that features.cc's bounds checks drop) around the cells.

    features.cc visits ``y = 1 .. cells_y * sbin - 2`` (likewise x) and reads the image at
    ``min(y, H - 2)``: the gradient is computed on the interior rows and columns that exist
    and the last one is repeated for the clamped rest.

    Up to ``_STRIP_PIXELS`` visited pixels are done in one pass, with cached index and weight
    arrays and the padding built into the gradient planes (on small patches the per-call
    overhead dominates). Larger images are done in strips of whole cell rows so that the
    temporaries stay in the cache (about 2x faster than whole-image arrays on a 768x576
    image).
    """
    height, width = image.shape[0] + 2 * pad, image.shape[1] + 2 * pad
    n_rows, n_cols = cells[0] * sbin - 2, cells[1] * sbin - 2  # visited pixels per axis
    rows_in, cols_in = min(n_rows, height - 2), min(n_cols, width - 2)  # of which interior
    dtype = _plane_dtype(image)
    padded = (cells[0] + 2, cells[1] + 2, _NUM_ORIENTATIONS)

    if n_rows * n_cols <= _STRIP_PIXELS:
        index, weights, source = _single_pass_layout(sbin, cells, (rows_in, cols_in))
        orient, mag = _gradients(_planes(image, pad, rows_in + 2, cols_in + 2, dtype))
        if source is not None:  # clamped coordinates repeat the last row/column
            orient, mag = orient.take(source), mag.take(source)
        index = index + orient.reshape(-1)
        weighted = weights * mag.reshape(-1)
        size = padded[0] * padded[1] * _NUM_ORIENTATIONS
        hist = np.bincount(index.reshape(-1), weighted.reshape(-1), minlength=size)
        return hist.reshape(padded)
    return _strip_histograms(image, sbin, cells, pad, (rows_in, cols_in))


def _strip_histograms(
    image: np.ndarray, sbin: int, cells: tuple[int, int], pad: int, interior: tuple[int, int]
) -> np.ndarray:
    """The padded float64 ``(cells_y + 2, cells_x + 2, 18)`` histograms, strip by strip."""
    if pad:
        image = np.pad(image, ((pad, pad), (pad, pad)) + ((0, 0),) * (image.ndim - 2), "edge")
    dtype = _plane_dtype(image)
    n_rows, n_cols = cells[0] * sbin - 2, cells[1] * sbin - 2  # visited pixels per axis
    rows_in, cols_in = interior
    cy, wy = _bilinear_weights(n_rows, sbin)
    cx, wx = _bilinear_weights(n_cols, sbin)
    wx = wx.astype(np.float32)
    padded = (cells[0] + 2, cells[1] + 2, _NUM_ORIENTATIONS)
    hist = np.zeros(padded, dtype=np.float64)

    strip = sbin * max(1, _STRIP_PIXELS // (sbin * n_cols))
    for start in range(0, rows_in, strip):
        stop = min(start + strip, rows_in)
        planes = _planes(image[start:], 0, stop - start + 2, cols_in + 2, dtype)
        orient, mag = (a[:, 1:-1] for a in _gradients(planes))
        end = n_rows if stop == rows_in else stop  # the last strip takes the clamped rows
        if end > stop or n_cols > cols_in:  # clamped coordinates repeat the last row/column
            pad_width = ((0, end - stop), (0, n_cols - cols_in))
            orient = np.pad(orient, pad_width, mode="edge")
            mag = np.pad(mag, pad_width, mode="edge")
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
    return hist


def _clip(values: np.ndarray) -> None:
    """``values = min(values, 0.2)`` in place, for a float32 array of at most 65536 values."""
    np.minimum(values, _CLIP_BLOCK[: values.size].reshape(values.shape), out=values)


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


def _fhog(image: np.ndarray, sbin: int, truncation_feature: bool, pad: int = 0) -> np.ndarray:
    """:func:`fhog` of a validated image edge-padded by ``pad`` pixels on every side."""
    height, width = image.shape[0] + 2 * pad, image.shape[1] + 2 * pad
    cells = (_c_round_div(height, sbin), _c_round_div(width, sbin))
    out_shape = (max(cells[0] - 2, 0), max(cells[1] - 2, 0))
    n_features = NUM_FEATURES + int(truncation_feature)
    feat = np.zeros((*out_shape, n_features), dtype=np.float32)
    if 0 in out_shape:  # nothing survives the dropped border ring (and H, W may be < 3)
        return feat

    # Feature-major (feature, row, column) layout over all the cells, the outer ring included
    # until the end: every step below is then a few long contiguous passes.
    hist = np.empty((27, *cells), dtype=np.float32)
    hist[:18] = _histograms(image, sbin, cells, pad)[1:-1, 1:-1].transpose(2, 0, 1)
    insensitive = np.add(hist[:9], hist[9:18], out=hist[18:])  # h[o] + h[o + 9]

    # Block energies: norm = sum_o (h[o] + h[o + 9])^2 per cell, summed over each 2x2 block.
    # With a ring of zero norms, block[a + 1, b + 1] is the block of cells (a..a+1, b..b+1)
    # and the ring of blocks around them is finite junk.
    norm = np.zeros((cells[0] + 2, cells[1] + 2), dtype=np.float32)
    np.einsum("kij,kij->ij", insensitive, insensitive, out=norm[1:-1, 1:-1])
    block = norm[:-1, :-1] + norm[1:, :-1] + norm[:-1, 1:] + norm[1:, 1:]
    inv = np.add(block, _EPS, dtype=np.float64)
    inv = np.divide(1.0, np.sqrt(inv, out=inv), out=inv).astype(np.float32)
    # The four blocks holding cell (y, x): block index offsets (1,1), (0,1), (1,0), (0,0) are
    # n1..n4 of features.cc (the order of the texture features).
    norms = (inv[1:, 1:], inv[:-1, 1:], inv[1:, :-1], inv[:-1, :-1])
    sums = np.empty((NUM_FEATURES, *cells), dtype=np.float32)
    # Bands of cell rows keep the (27, rows, cells_x) temporary in the cache (about 2x faster
    # than one (4, 27, cells_y, cells_x) product on large maps).
    band = max(1, _NORM_BAND_CELLS // cells[1])
    clipped = np.empty((27, min(band, cells[0]), cells[1]), dtype=np.float32)
    for top in range(0, cells[0], band):
        rows = slice(top, min(top + band, cells[0]))
        h_k = clipped[:, : rows.stop - top]
        total = sums[:27, rows]
        for k, n_k in enumerate(norms):
            np.multiply(hist[:, rows], n_k[rows], out=h_k)
            _clip(h_k)  # h_k = min(h * n_k, 0.2)
            if k:
                total += h_k
            else:
                np.copyto(total, h_k)
            np.add.reduce(h_k[:18], axis=0, out=sums[27 + k, rows])  # t_k
    sums[:27] *= np.float32(0.5)  # 0.5 * (h1 + h2 + h3 + h4)
    sums[27:] *= _TEXTURE_WEIGHT  # 0.2357 * t_k
    feat[..., :NUM_FEATURES] = sums[:, 1:-1, 1:-1].transpose(1, 2, 0)
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
    return _fhog(image, sbin, truncation_feature=False, pad=sbin)
