"""Filter responses: the correlation of HOG filters with a feature map (voc-release5 ``fconv``).

The response of an ``(h, w, C)`` filter ``F`` at ``(y, x)`` of an ``(H, W, C)`` map ``G`` is

    R[y, x] = sum_{dy < h, dx < w, c < C} F[dy, dx, c] G[y + dy, x + dx, c]

(Felzenszwalb et al., PAMI 2010, §3: the dot product of the filter with the subwindow), defined
for ``0 <= y <= H - h`` and ``0 <= x <= W - w`` (``fconv``'s valid responses).

Computed as one matrix product per band of rows, then shifted sums: with ``T = G @ F^T`` (every
cell of the band against every filter tap, ``(h w K, cells)``, BLAS ``sgemm``),
``R_k[y, x] = sum_{dy, dx} T[k, dy, dx][y + dy, x + dx]``, ``h w`` vectorised additions per
band for all ``K`` filters of one size. That does the ``h w C`` multiply-adds per position at
BLAS speed (~30 GMAC/s on one core here, 80% of it in the product). Measured on a 320x396x32
map with sixteen 6x6 filters: 76 ms, against 175 ms for an im2col product and ~1.1 s for
``cv2.matchTemplate`` on 32 channels filter by filter.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["filter_responses"]

_BAND_BYTES = 48 * 2**20  # size of the tap-product buffer of one band of rows


def _group_responses(
    features: np.ndarray,
    filters: np.ndarray,
    rows: tuple[int, int],
    cols: tuple[int, int],
) -> np.ndarray:
    """Responses of ``K`` same-size filters on the grid ``rows x cols`` (all inside valid)."""
    k, fh, fw, c = filters.shape
    r0, r1 = rows
    c0, c1 = cols
    nr, nc = r1 - r0, c1 - c0
    out = np.empty((k, nr, nc), dtype=np.float32)
    if nr <= 0 or nc <= 0:
        return out
    taps = np.ascontiguousarray(filters.transpose(1, 2, 0, 3).reshape(fh * fw * k, c))
    width = nc + fw - 1  # feature columns the grid needs
    band = max(1, _BAND_BYTES // (4 * fh * fw * k * width) - fh + 1)
    for start in range(0, nr, band):
        stop = min(nr, start + band)
        n = stop - start
        block = features[r0 + start : r0 + stop + fh - 1, c0 : c0 + width]
        cells = block.reshape(-1, c)  # a view when the band spans whole rows
        products = (taps @ cells.T).reshape(fh, fw, k, n + fh - 1, width)
        acc = out[:, start:stop]
        np.copyto(acc, products[0, 0, :, :n, :nc])
        for dy in range(fh):
            for dx in range(fw):
                if dy or dx:
                    acc += products[dy, dx, :, dy : dy + n, dx : dx + nc]
    return out


def filter_responses(
    features: np.ndarray,
    filters: Sequence[np.ndarray],
    rows: tuple[int, int] | None = None,
    cols: tuple[int, int] | None = None,
) -> list[np.ndarray]:
    """Responses of several filters on one feature map, on a common grid of positions.

    Parameters
    ----------
    features:
        ``(H, W, C)`` float32 feature map (a padded pyramid level).
    filters:
        ``(h_k, w_k, C)`` float32 filters (sizes may differ).
    rows, cols:
        Half-open ranges ``(start, stop)`` of response positions to compute; default: the
        largest valid grid, ``0 .. H - min h`` by ``0 .. W - min w``. Positions outside a
        filter's valid range (``y > H - h_k`` or ``y < 0``, likewise ``x``) get ``-inf``, as the
        ``-inf`` padding of ``gdetect_dp.m``'s ``filter_responses``.

    Returns
    -------
    list of np.ndarray
        One ``(len(rows), len(cols))`` float32 array per filter.
    """
    features = np.asarray(features, dtype=np.float32)
    if features.ndim != 3:
        raise ValueError(f"features must have shape (H, W, C), got {features.shape}")
    height, width, channels = features.shape
    if not filters:
        return []
    for f in filters:
        if f.ndim != 3 or f.shape[2] != channels:
            raise ValueError(f"filters must have shape (h, w, {channels}), got {f.shape}")
    min_h = min(f.shape[0] for f in filters)
    min_w = min(f.shape[1] for f in filters)
    rows = rows if rows is not None else (0, max(height - min_h + 1, 0))
    cols = cols if cols is not None else (0, max(width - min_w + 1, 0))
    nr, nc = max(rows[1] - rows[0], 0), max(cols[1] - cols[0], 0)
    out: list[np.ndarray | None] = [None] * len(filters)
    groups: dict[tuple[int, int], list[int]] = {}
    for i, f in enumerate(filters):
        groups.setdefault(f.shape[:2], []).append(i)
    for (fh, fw), members in groups.items():
        # the part of the requested grid where these filters fit inside the map
        vr = (max(rows[0], 0), min(rows[1], height - fh + 1))
        vc = (max(cols[0], 0), min(cols[1], width - fw + 1))
        stack = np.stack([filters[i] for i in members]).astype(np.float32, copy=False)
        inner = _group_responses(features, stack, vr, vc)
        for j, i in enumerate(members):
            if vr == rows and vc == cols:
                out[i] = inner[j]
                continue
            full = np.full((nr, nc), -np.inf, dtype=np.float32)
            if vr[1] > vr[0] and vc[1] > vc[0]:
                full[vr[0] - rows[0] : vr[1] - rows[0], vc[0] - cols[0] : vc[1] - cols[0]] = inner[
                    j
                ]
            out[i] = full
    return [o for o in out if o is not None]
