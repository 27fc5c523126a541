"""Felzenszwalb HOG features (Felzenszwalb et al., PAMI 2010, §6), as voc-release5 computes them.

The 31 features of a cell are, in order (§6.2 and voc-release5 ``features/features.cc``):

* ``0..17``  contrast-sensitive orientations: bin ``o`` is the direction ``o * 20°`` of the
  gradient, measured from the +x (column, rightwards) axis towards +y (row, downwards);
* ``18..26`` contrast-insensitive orientations: bin ``18 + o`` pools ``o`` and ``o + 9``
  (``o * 20°`` modulo 180°);
* ``27..30`` texture (gradient energy) features: ``0.2357`` times the sum of the 18
  contrast-sensitive values under each of the four block normalisations;
* ``31`` (only with ``truncation_feature=True``) the voc-release5 "truncation" channel: 0 in
  the image's cells, 1 in the cells of a margin (:func:`fhog_cells`' ``margin``, the DPM
  feature pyramid's padding).

Each cell histogram is normalised by the energy of each of the four 2x2 cell blocks that contain
it, clipped at 0.2 and the four results summed with weight 0.5 (the analytic projection of the
36-dimensional Dalal-Triggs vector, §6.3).

The computation follows voc-release5 step for step, in numba-compiled kernels (for speed: the
per-pixel channel choice, orientation search and bilinear votes took numpy a dozen passes over
whole-image temporaries; the kernels go through the image a few rows at a time, in the cache,
and are 3-6x faster). They run single-threaded and release the GIL, so callers can compute
pyramid levels in threads. :func:`fhog_cells` gives the maps of several cell sizes of one image
from one pass over its pixels: the gradient, orientation and magnitude of each pixel (steps 2-3,
most of the work) are computed once and vote into the histograms of every size, which are
normalised row by row as they complete; :func:`fhog` is its one-size case.

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

from collections.abc import Sequence

import numba
import numpy as np

from tracking.compiled import call_kernel
from tracking.types import check_pixel_values, is_int

__all__ = ["NUM_FEATURES", "fhog", "fhog_cells", "hog_feature_map"]

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

NUM_FEATURES = 31
"""Features per cell without the truncation channel (18 + 9 + 4)."""


@numba.njit(cache=True, nogil=True)
def _c_round_div(n: int, d: int) -> int:
    """``round(n / d)`` for non-negative ints with C's rounding (halves up, unlike ``round``)."""
    return (2 * n + d) // (2 * d)


def _check_cell_size(cell_size: object) -> int:
    """The cell size as a positive int, or ValueError."""
    if not is_int(cell_size):
        raise ValueError(f"cell_size must be a positive int, got {cell_size!r}")
    if cell_size < 1:
        raise ValueError(f"cell_size must be a positive int, got {cell_size}")
    return int(cell_size)


def _check_margin(margin: object) -> tuple[int, int]:
    """``(rows, columns)`` of a margin as non-negative ints, or ValueError."""
    message = f"margin must be two non-negative ints (rows, columns), got {margin!r}"
    rows: object
    cols: object
    try:
        rows, cols = margin  # type: ignore[misc]  # not a pair: the ValueError below
    except (TypeError, ValueError):
        raise ValueError(message) from None
    if not (is_int(rows) and is_int(cols) and rows >= 0 and cols >= 0):
        raise ValueError(message)
    return int(rows), int(cols)


def _validated(image: np.ndarray) -> np.ndarray:
    """``image`` as an array of shape ``(H, W)`` or ``(H, W, 3)`` with finite real values."""
    image = np.asarray(image)
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {image.shape}")
    check_pixel_values(image)
    return image


def _pixels(image: np.ndarray) -> np.ndarray:
    """A validated image as the kernels take it: ``(H, W, C)``, uint8 or float32, any strides.

    The kernels read each pixel once, converting it to float32 (exactly for uint8), so neither
    a conversion of 8-bit images nor a contiguous copy would pay for itself (a copy of a BGR
    -> RGB view costs about as much as the whole kernel); other dtypes become float32, as the
    gradients are taken in single precision. A grayscale image becomes ``C = 1``: one channel
    gives the same features as three equal ones (ties go to the first channel) for a third of
    the work.
    """
    if image.dtype != np.uint8:
        image = image.astype(np.float32, copy=False)
    return image[:, :, np.newaxis] if image.ndim == 2 else image


@numba.njit(cache=True, nogil=True)
def _padded_row(image, pad, y, line):  # pragma: no cover - compiled
    """Fill ``line`` (float32 ``(C, n)``) with columns ``0 .. n - 1`` of row ``y`` of ``image``
    edge-padded by ``pad`` pixels on every side, one channel per row of ``line``.

    ``image`` is ``(H, W, C)``; padded pixel ``(y, x)`` is image pixel ``(y - pad, x - pad)``
    with both coordinates clamped to the image, which is edge replication without a padded
    copy. uint8 values convert to float32 exactly.
    """
    height, width, channels = image.shape
    n = line.shape[1]
    source = image[min(max(y - pad, 0), height - 1)]
    first, stop = min(pad, n), min(pad + width, n)  # padded columns that are image columns
    for c in range(channels):
        out, inside = line[c], line[c, first:stop]
        out[:first] = source[0, c]
        # A loop from 0 over slices: the compiler then knows the indices are non-negative and
        # skips the negative-index wraparound (twice faster).
        values = source[: stop - first, c]
        for x in range(inside.shape[0]):
            inside[x] = values[x]
        out[stop:] = source[width - 1, c]


@numba.njit(cache=True, nogil=True)
def _row_gradients(above, row, below, gx, gy, energy):  # pragma: no cover - compiled
    """Centred differences of the strongest channel along one image row (features.cc).

    ``above``, ``row``, ``below`` are three consecutive rows as :func:`_padded_row` gives them,
    ``(C, n + 2)``; column ``j`` of the outputs (float32 ``(n,)``) is pixel ``j + 1``:
    ``gx = row[j + 2] - row[j]``, ``gy = below[j + 1] - above[j + 1]`` of the channel with the
    largest ``energy = gx^2 + gy^2`` (strict ``>``: ties go to the first channel). Selects
    rather than branches, as the winning channel is unpredictable; the loops vectorise.
    """
    n = gx.shape[0]
    for c in range(row.shape[0]):
        for j in range(n):
            dx = row[c, j + 2] - row[c, j]
            dy = below[c, j + 1] - above[c, j + 1]
            value = dx * dx + dy * dy
            better = c == 0 or value > energy[j]
            gx[j] = dx if better else gx[j]
            gy[j] = dy if better else gy[j]
            energy[j] = value if better else energy[j]


@numba.njit(cache=True, nogil=True)
def _orientations(gx, gy, orientation):  # pragma: no cover - compiled
    """Orientation bins (int32, 0..17) of float32 gradients ``(gx, gy)``, as features.cc snaps
    them.

    The first o maximising ``|uu[o] dx + vv[o] dy|``, then o if that dot is positive, o + 9 if
    negative: features.cc's "if (dot > best) ... else if (-dot > best)" chain, as a strictly
    larger ``|dot|`` can pass only one of its two branches. The dots are float32 products and
    sums (no fused multiply-add), which makes every decision exact for 8-bit images. The 9
    directions are an inner loop of selects on locals, which the compiler unrolls and
    vectorises across pixels: a per-pixel chain of 9 unpredictable branches was the slowest
    part of the computation, and one pass over the row per direction (keeping the best so far
    in arrays) took 4 times as long as this.
    """
    for j in range(gx.shape[0]):
        dx, dy = gx[j], gy[j]
        best, snapped = np.float32(0.0), np.int32(0)
        for o in range(9):
            dot = _UU[o] * dx + _VV[o] * dy
            magnitude = abs(dot)
            better = magnitude > best
            best = magnitude if better else best
            candidate = np.int32(o) if dot > 0 else np.int32(o + 9)
            snapped = candidate if better else snapped
        orientation[j] = snapped


@numba.njit(cache=True, nogil=True)
def _bilinear_weights(sbin, cell, weight):  # pragma: no cover - compiled
    """Fill ``cell`` and ``weight`` (int64 and float64 ``(n,)``) with the cell index and weight
    of the pixels ``1 .. n`` along one axis (features.cc).

    ``xp = (x + 0.5) / sbin - 0.5``; the pixel gives ``1 - frac(xp)`` to cell ``floor(xp)`` and
    ``frac(xp)`` to the next. The index is ``floor(xp) + 1``, i.e. into a cell array padded by
    one cell on each side (cells outside ``0 .. cells - 1`` are later dropped, as the bounds
    checks of features.cc drop them).
    """
    for i in range(cell.shape[0]):
        xp = (i + 1.5) / sbin - 0.5
        floor = np.floor(xp)
        cell[i] = int(floor) + 1
        weight[i] = xp - floor


@numba.njit(cache=True, nogil=True)
def _vote(windows, k, row, wy, orientation, magnitude, cell_x, far_x, n):  # pragma: no cover
    """Add one visited row of pixels to the float64 histograms of its two cell rows, for cell
    size ``k`` (index ``k`` of the stacked per-size arrays of :func:`_features`).

    ``windows[k]`` is ``(2, cells_x + 2, 18)`` (or wider), a ring of two padded cell rows, row
    ``c`` in ``c % 2``: ``row``, the pixel row's cell row, and the next; the pixel row's weight
    is ``wy`` (:func:`_bilinear_weights`). The size visits ``n`` pixels, their cells and
    weights the first ``n`` of ``cell_x[k]`` and ``far_x[k]``. Pixel ``j`` has the bin
    ``orientation[min(j, m - 1)]`` and the float32 ``magnitude`` at the same index, ``m`` their
    length: pixels beyond the interior repeat the last one's gradient (features.cc clamps
    their coordinates). Each vote is ``(y weight * x weight) * magnitude``, as features.cc
    computes it. (One array: with the two rows as two arrays, the compiler cannot tell that
    they never overlap, and the histograms took 20% longer.)
    """
    vy = 1.0 - wy
    top, bottom = row % 2, (row + 1) % 2
    last = orientation.shape[0] - 1
    for j in range(n):
        i = min(j, last)
        o = orientation[i]
        value = np.float64(magnitude[i])
        cx, wx = cell_x[k, j], far_x[k, j]
        vx = 1.0 - wx
        windows[k, top, cx, o] += vy * vx * value
        windows[k, top, cx + 1, o] += vy * wx * value
        windows[k, bottom, cx, o] += wy * vx * value
        windows[k, bottom, cx + 1, o] += wy * wx * value


@numba.njit(cache=True, nogil=True)
def _store_cell_row(windows, hists, norms, k, r, cells_x):  # pragma: no cover - compiled
    """Store image cell row ``r`` of size ``k`` (padded row ``r + 1``, in
    ``windows[k, (r + 1) % 2]``) as float32 in ``hists[k, r % 2]``, its cell energies in
    ``norms[k, 0, r % 2]`` and, with row ``r - 1``'s, the inverse norms of block row ``r - 1``
    in ``norms[k, 1, (r - 1) % 2]``.

    The energy of a cell is ``sum_o (h[o] + h[o + 9])^2`` (of the contrast-insensitive
    histogram), a block's the sum over its 2x2 cells in features.cc's order, both in float32;
    the inverse is ``1 / sqrt(energy + eps)``, the square root taken in double.
    """
    window, hist, below = windows[k, (r + 1) % 2], hists[k, r % 2], norms[k, 0, r % 2]
    for x in range(cells_x):
        energy = np.float32(0.0)  # a local sum: no chain of loads and stores through below
        for o in range(_NUM_ORIENTATIONS):
            hist[x, o] = window[x + 1, o]
        for o in range(9):
            value = hist[x, o] + hist[x, o + 9]
            energy += value * value
        below[x] = energy
    if r >= 1:
        above, inverse = norms[k, 0, (r - 1) % 2], norms[k, 1, (r - 1) % 2]
        for x in range(cells_x - 1):
            block = above[x] + below[x] + above[x + 1] + below[x + 1]
            inverse[x] = np.float32(1.0 / np.sqrt(np.float64(block) + _EPS))


@numba.njit(cache=True, nogil=True)
def _clipped(value, inverse):  # pragma: no cover - compiled
    """``min(value * inverse, 0.2)`` in float32: one normalised, truncated value (§6.2)."""
    normalised = value * inverse
    return normalised if normalised < _CLIP else _CLIP


@numba.njit(cache=True, nogil=True)
def _normalised_row(hists, norms, k, r, out):  # pragma: no cover - compiled
    """Fill ``out[..., :31]``, the row of features of size ``k``'s histogram row ``r`` (in
    ``hists[k, r % 2]``), with the inverse norms of block rows ``r - 1`` and ``r`` in
    ``norms[k, 1]`` (:func:`_store_cell_row`); §6.2, §6.3.

    Output cell ``x`` is histogram cell ``x + 1`` (the outer ring is dropped); each of its 27
    orientation values is normalised by the four blocks that contain it (features.cc's n1..n4,
    the order of the texture features), clipped at 0.2 and the four results summed with weight
    0.5; texture feature k is 0.2357 times the sum of the 18 contrast-sensitive values under
    block k. All in float32, as voc-release5 stores them.

    The texture sums are a second pass over the row: in one loop with the orientation values
    they kept it from vectorising, and their chains of dependent additions overlap better
    when nothing else sits between consecutive cells.
    """
    hist, above, below = hists[k, r % 2], norms[k, 1, (r - 1) % 2], norms[k, 1, r % 2]
    half = np.float32(0.5)
    for x in range(out.shape[0]):
        h, cell = hist[x + 1], out[x]
        n1, n2, n3, n4 = below[x + 1], above[x + 1], below[x], above[x]
        for o in range(27):
            # contrast-sensitive h[o], then contrast-insensitive h[o] + h[o + 9]
            value = h[o] if o < _NUM_ORIENTATIONS else h[o - 18] + h[o - 9]
            total = _clipped(value, n1) + _clipped(value, n2) + _clipped(value, n3)
            cell[o] = (total + _clipped(value, n4)) * half
    for x in range(out.shape[0]):
        h, cell = hist[x + 1], out[x]
        n1, n2, n3, n4 = below[x + 1], above[x + 1], below[x], above[x]
        t1 = t2 = t3 = t4 = np.float32(0.0)
        for o in range(_NUM_ORIENTATIONS):
            t1 += _clipped(h[o], n1)
            t2 += _clipped(h[o], n2)
            t3 += _clipped(h[o], n3)
            t4 += _clipped(h[o], n4)
        cell[27] = t1 * _TEXTURE_WEIGHT
        cell[28] = t2 * _TEXTURE_WEIGHT
        cell[29] = t3 * _TEXTURE_WEIGHT
        cell[30] = t4 * _TEXTURE_WEIGHT


@numba.njit(cache=True, nogil=True)
def _next_cell_row(windows, hists, norms, k, row, feat, margin_y, margin_x):  # pragma: no cover
    """Finish size ``k``'s complete padded cell row ``row`` (``windows[k, row % 2]``), then
    empty it for row ``row + 2``.

    ``feat`` is the size's float32 map, ``(cells_y - 2, cells_x - 2, n)`` inside a margin of
    ``margin_y`` rows and ``margin_x`` columns. Padded rows 0 and ``cells_y + 1`` are the ring
    outside the image and are dropped (features.cc's bounds checks); image cell row
    ``r = row - 1`` is stored (:func:`_store_cell_row`) and completes the map's row ``r - 2``
    (histogram row ``r - 1``, normalised by block rows ``r - 2`` and ``r - 1``). Normalising
    as the rows complete needs no image-sized histogram array (whose fresh pages cost more
    than the normalisation itself) and finds the rows in the cache.
    """
    rows, cols = feat.shape[0] - 2 * margin_y, feat.shape[1] - 2 * margin_x
    cells_x = cols + 2
    r = row - 1
    if 0 <= r < rows + 2:
        _store_cell_row(windows, hists, norms, k, r, cells_x)
        if r >= 2:
            out = feat[margin_y + r - 2, margin_x : margin_x + cols]  # inside the margin
            _normalised_row(hists, norms, k, r - 1, out)
    # An array assignment: numba fills those fastest (a loop took 3 times as long). Emptying the
    # row rather than shifting the window down saves a copy per cell row.
    windows[k, row % 2, : cells_x + 2] = 0.0


@numba.njit(cache=True, nogil=True)
def _features(image, sbins, pad, n_features, margin_y, margin_x):  # pragma: no cover - compiled
    """The float32 ``(max(cells_y - 2, 0), max(cells_x - 2, 0), n_features)`` maps of ``image``
    edge-padded by ``pad`` pixels on every side, one per cell size in the int64 ``sbins``, all
    from one pass over the pixels, each inside a margin of ``margin_y`` and ``margin_x`` cells
    of zeros. The 32nd (truncation) channel, if any, stays 0.

    ``image`` is as :func:`_pixels` gives it. For each cell size, features.cc visits
    ``y = 1 .. cells_y * sbin - 2`` (likewise x) and reads the image at ``min(y, H - 2)``: the
    gradients are computed on the interior rows and columns that exist, and the last one is
    repeated for the clamped rest. A pixel's gradient, orientation and magnitude do not
    depend on the cell size, so they are computed once, on the union of the visited rows and
    columns, and every size votes with them. That is exact for each size: a size visits fewer
    pixels than the union only if it stops before the last interior row (column), so it never
    clamps; a size that clamps does so at the last interior one, as the union does
    (:func:`_vote` repeats the last column).

    Everything works on a few rows at a time, so it stays in the cache and large images need
    no large temporaries: the image is read into a ring of three float32 pixel rows (each
    pixel converted once); each size's votes go to a float64 window of the two cell rows that
    the pixel row touches (the cells outside the image, in a ring around them, collect the
    votes that features.cc's bounds checks drop); each cell row is normalised as soon as the
    rows below it are complete (:func:`_next_cell_row`).

    The sizes' state is stacked in arrays padded to the largest size, index ``k`` for size
    ``k``, and the kernels take the whole arrays and ``k``: a view (``windows[k]``) or a list
    element passed to a function costs a pair of atomic reference counts per call (seen in the
    compiled code), which would be paid per size and pixel row.
    """
    height, width, channels = image.shape[0] + 2 * pad, image.shape[1] + 2 * pad, image.shape[2]
    feats = []
    # Of the sizes with a non-empty map: index into feats, sbin, visited pixel rows and columns.
    grids = np.empty((len(sbins), 4), dtype=np.int64)
    n_sizes = n_rows = n_cols = cells = 0  # of them all, the largest
    for index, sbin in enumerate(sbins):
        cells_y, cells_x = _c_round_div(height, sbin), _c_round_div(width, sbin)
        shape = (max(cells_y - 2, 0) + 2 * margin_y, max(cells_x - 2, 0) + 2 * margin_x)
        # written in place inside the margin: a padded copy made afterwards cost the DPM
        # pyramid about 40 ms per PETS frame
        feats.append(np.zeros((*shape, n_features), dtype=np.float32))
        if min(cells_y, cells_x) < 3:  # nothing survives the dropped border ring
            continue
        rows, cols = sbin * cells_y - 2, sbin * cells_x - 2
        grids[n_sizes] = index, sbin, rows, cols
        n_sizes += 1
        n_rows, n_cols, cells = max(n_rows, rows), max(n_cols, cols), max(cells, cells_x)
    if n_sizes == 0:
        return feats
    cell_y, far_y = np.empty((n_sizes, n_rows), np.int64), np.empty((n_sizes, n_rows))
    cell_x, far_x = np.empty((n_sizes, n_cols), np.int64), np.empty((n_sizes, n_cols))
    for k in range(n_sizes):
        _, sbin, rows, cols = grids[k]
        _bilinear_weights(sbin, cell_y[k, :rows], far_y[k, :rows])
        _bilinear_weights(sbin, cell_x[k, :cols], far_x[k, :cols])
    windows = np.zeros((n_sizes, 2, cells + 2, _NUM_ORIENTATIONS), dtype=np.float64)
    hists = np.empty((n_sizes, 2, cells, _NUM_ORIENTATIONS), dtype=np.float32)
    norms = np.empty((n_sizes, 2, 2, cells), dtype=np.float32)  # energies, inverses
    current = np.zeros(n_sizes, dtype=np.int64)  # per size, the cell row of the pixel row
    rows_in = min(n_rows, height - 2)  # visited rows that are interior
    cols_in = min(n_cols, width - 2)

    lines = np.empty((3, channels, cols_in + 2), dtype=np.float32)  # padded row y in y % 3
    _padded_row(image, pad, 0, lines[0])
    _padded_row(image, pad, 1, lines[1])
    gx = np.empty(cols_in, dtype=np.float32)
    gy = np.empty_like(gx)
    magnitude = np.empty_like(gx)
    orientation = np.empty(cols_in, dtype=np.int32)
    for i in range(n_rows):
        y = i + 1  # the visited row; past rows_in, the gradients of row rows_in are reused
        if y <= rows_in:
            _padded_row(image, pad, y + 1, lines[(y + 1) % 3])
            _row_gradients(lines[(y - 1) % 3], lines[y % 3], lines[(y + 1) % 3], gx, gy, magnitude)
            _orientations(gx, gy, orientation)
            np.sqrt(magnitude, magnitude)
        for k in range(n_sizes):
            if i >= grids[k, 2]:  # past the rows this size visits
                continue
            # Every cell row is finished in turn, even one that no pixel row votes into (image
            # row 0 with 1-pixel cells), as it is normalised too.
            while cell_y[k, i] != current[k]:  # no later pixel row votes into the current one
                feat = feats[grids[k, 0]]
                _next_cell_row(windows, hists, norms, k, current[k], feat, margin_y, margin_x)
                current[k] += 1
            # The gradient row is longer than this size's visited columns only where the size
            # does not clamp, so _vote's repetition of the last pixel is the size's clamping.
            wy = far_y[k, i]
            _vote(windows, k, current[k], wy, orientation, magnitude, cell_x, far_x, grids[k, 3])
    for k in range(n_sizes):
        feat = feats[grids[k, 0]]
        _next_cell_row(windows, hists, norms, k, current[k], feat, margin_y, margin_x)
        _next_cell_row(windows, hists, norms, k, current[k] + 1, feat, margin_y, margin_x)
    return feats


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
    sbin = _check_cell_size(cell_size)
    return _fhog_cells(_validated(image), [sbin], truncation_feature)[0]


def fhog_cells(
    image: np.ndarray,
    cell_sizes: Sequence[int],
    *,
    truncation_feature: bool = False,
    margin: tuple[int, int] = (0, 0),
    checked: bool = False,
) -> list[np.ndarray]:
    """:func:`fhog` of one image for several cell sizes, with one pass over the pixels.

    Equal, bit for bit, to ``[fhog(image, s, truncation_feature=truncation_feature) for s in
    cell_sizes]``, but each pixel's gradient, orientation and magnitude are computed once and
    vote into the histograms of every cell size (the DPM feature pyramid takes cells of 2, 4
    and 8 pixels on the same resized image). Repeated sizes give equal, separate arrays.

    Parameters
    ----------
    image:
        As for :func:`fhog`.
    cell_sizes:
        Cell sides in pixels, positive ints, in any order; empty gives an empty list.
    truncation_feature:
        As for :func:`fhog`.
    margin:
        ``(rows, columns)`` of cells of zeros around each map, written in place (the DPM
        feature pyramid's padding, voc-release5 ``featpyramid.m``); with
        ``truncation_feature``, the truncation channel is 1 in the margin, as it marks cells
        outside the image.
    checked:
        The caller has already checked ``image`` (an integer or float array of shape
        ``(H, W)`` or ``(H, W, 3)`` with finite values), so it is not checked again: the DPM
        pyramid checks a frame once, not each of its dozens of resized images (for a region
        of interest the checks of its small images took about 3% of the time).

    Returns
    -------
    list of np.ndarray
        One float32 map per cell size, in the order of ``cell_sizes``, shaped as :func:`fhog`
        shapes it (empty along an axis of fewer than 2.5 cells) plus twice the margin.

    Raises
    ------
    ValueError
        As :func:`fhog`; also when ``cell_sizes`` is not a sequence (a single int) or
        ``margin`` is not two non-negative ints.
    """
    message = f"cell_sizes must be a sequence of positive ints, got {cell_sizes!r}"
    if isinstance(cell_sizes, str | bytes):
        raise ValueError(message)
    try:
        sizes = list(cell_sizes)
    except TypeError:  # an int, None, a 0-d array
        raise ValueError(message) from None
    sbins = [_check_cell_size(s) for s in sizes]
    rows, cols = _check_margin(margin)
    image = image if checked else _validated(image)
    maps = _fhog_cells(image, sbins, truncation_feature, margin=(rows, cols))
    if truncation_feature:  # the margin's cells are outside the image
        for feat in maps:
            height, width = feat.shape[:2]
            feat[:rows, :, NUM_FEATURES] = 1.0
            feat[height - rows :, :, NUM_FEATURES] = 1.0
            feat[:, :cols, NUM_FEATURES] = 1.0
            feat[:, width - cols :, NUM_FEATURES] = 1.0
    return maps


def _fhog_cells(
    image: np.ndarray,
    sbins: list[int],
    truncation_feature: bool,
    pad: int = 0,
    margin: tuple[int, int] = (0, 0),
) -> list[np.ndarray]:
    """:func:`fhog_cells` of a validated image edge-padded by ``pad`` pixels on every side."""
    if len(sbins) > 1 and len(set(sbins)) < len(sbins):  # each size once; repeats get copies
        distinct = list(dict.fromkeys(sbins))
        maps = _fhog_cells(image, distinct, truncation_feature, pad, margin)
        computed = dict(zip(distinct, maps, strict=True))
        out, seen = [], set()
        for sbin in sbins:  # the first of a repeated size gets the map, later ones copies
            out.append(computed[sbin].copy() if sbin in seen else computed[sbin])
            seen.add(sbin)
        return out
    if not sbins:
        return []
    n_features = NUM_FEATURES + int(truncation_feature)
    sizes = np.array(sbins, dtype=np.int64)
    return call_kernel(_features, _pixels(image), sizes, pad, n_features, margin[0], margin[1])


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
    return _fhog_cells(image, [sbin], truncation_feature=False, pad=sbin)[0]
