"""Generalized distance transforms of part scores under quadratic deformation costs.

The score of a part at its anchor ``p`` is the best trade-off between the part filter's
response ``f`` and the cost of moving the part away from the anchor (Felzenszwalb et al.,
PAMI 2010, eq. 4-5; Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled Functions",
Theory of Computing 8, 2012):

    D(p) = max_q f(q) - d(p - q),      d(t) = a t^2 + b t,   a > 0,

with ``t = p - q`` (anchor minus placement, voc-release5's ``dt.cc``/``bounded_dt.cc``). In 2-D
the cost is separable, ``d_x(dx) + d_y(dy)``, so the transform is one 1-D pass along y followed
by one along x; the argmax placement is tracked through both passes.

Two variants:

* :func:`distance_transform` -- the exact, unbounded transform in linear time: the lower
  envelope of the parabolas ``q -> -f(q) + d(p - q)`` (F&H, Algorithm 1). The envelope of one
  line is built sequentially along that line, so the loop runs over the ``n`` positions of the
  axis while every line (all rows, all parts) advances together as numpy vectors; reading the
  envelope is one ``searchsorted`` for all lines.
* :func:`bounded_distance_transform` -- voc-release5's ``bounded_dt.cc``: the same maximum over
  displacements ``|t| <= s`` only (release 5 uses ``s = 4`` cells); ``2 s + 1`` vectorised
  shifted maxima per axis, optionally only at a regular sub-grid of outputs (the root positions
  need the part table at every second cell).

``-inf`` inputs (positions where a filter does not fit) are never chosen unless a whole
window/line is ``-inf``, in which case the output is ``-inf``.
"""

from __future__ import annotations

import numpy as np

from tracking.types import is_int

__all__ = ["bounded_distance_transform", "distance_transform", "distance_transform_1d"]

_BIG = 1e30  # stands in for +inf in the envelope arithmetic (minimisation form)


def _weights(deformation: object, count: int) -> np.ndarray:
    w = np.asarray(deformation, dtype=np.float64)
    if w.shape == (4,):
        w = np.broadcast_to(w, (count, 4))
    if w.shape != (count, 4):
        raise ValueError(f"deformation must have shape (4,) or ({count}, 4), got {w.shape}")
    if not (np.all(np.isfinite(w)) and np.all(w[:, [0, 2]] > 0)):
        raise ValueError(f"deformation weights must be finite with a_x, a_y > 0, got {w.tolist()}")
    return w


def distance_transform_1d(
    values: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``D[r, p] = max_q values[r, q] - a[r] (p - q)^2 - b[r] (p - q)`` for every line ``r``.

    Felzenszwalb & Huttenlocher's lower-envelope algorithm in the minimisation form
    ``-D(p) = min_q g(q) + a (p - q)^2 + b (p - q)``, ``g = -f``: completing the square,
    ``a t^2 + b t = a (t + b / 2a)^2 - b^2 / 4a``, so the envelope of the parabolas of curvature
    ``a`` with vertices at the integers ``q`` is read at ``p + b / 2a``. Two parabolas from
    ``q`` and ``v`` intersect at ``s = ((g(q) + a q^2) - (g(v) + a v^2)) / (2 a (q - v))``.

    Parameters
    ----------
    values:
        ``(R, n)`` scores; ``-inf`` marks positions that cannot be chosen.
    a, b:
        ``(R,)`` cost weights per line, ``a > 0``.

    Returns
    -------
    out : np.ndarray
        ``(R, n)`` float64 transformed scores.
    arg : np.ndarray
        ``(R, n)`` int64 index ``q`` of the maximising placement.
    """
    f = np.asarray(values, dtype=np.float64)
    lines, n = f.shape
    a = np.asarray(a, dtype=np.float64).reshape(lines)
    b = np.asarray(b, dtype=np.float64).reshape(lines)
    if n == 0 or lines == 0:
        return np.full(f.shape, -np.inf), np.zeros(f.shape, dtype=np.int64)
    g = np.where(np.isneginf(f), _BIG, -f)
    positions = np.arange(n, dtype=np.float64)
    # Position-major layout: row q of h_t holds g(q) + a q^2 of every line, contiguous; the
    # envelope of line r is vertex[0..k_r, r] (its parabolas) and bound[0..k_r + 1, r] (where
    # each starts to be the lowest), read and written through flat indices k * lines + r.
    h_t = np.ascontiguousarray((g + a[:, None] * positions**2).T)
    vertex = np.zeros((n, lines), dtype=np.int64)
    bound = np.full((n + 1, lines), np.inf)
    bound[0] = -np.inf
    h_flat, v_flat, z_flat = h_t.ravel(), vertex.ravel(), bound.ravel()
    rows = np.arange(lines)
    k = np.zeros(lines, dtype=np.int64)
    two_a = 2.0 * a
    for q in range(1, n):
        hq = h_t[q]
        v = v_flat[k * lines + rows]
        s = (hq - h_flat[v * lines + rows]) / (two_a * (q - v))
        active = np.flatnonzero(s <= z_flat[k * lines + rows])
        while active.size:  # the new parabola hides the envelope's last one: pop it
            k[active] -= 1
            ka = k[active]
            va = v_flat[ka * lines + active]
            s[active] = (hq[active] - h_flat[va * lines + active]) / (two_a[active] * (q - va))
            active = active[s[active] <= z_flat[ka * lines + active]]
        k += 1
        index = k * lines + rows
        v_flat[index] = q
        z_flat[index] = s
        z_flat[index + lines] = np.inf
    vertex, bound = vertex.T, bound.T
    # entries past each line's last breakpoint may be stale from parabolas popped later
    bound = np.where(np.arange(n + 1)[None, :] > (k + 1)[:, None], np.inf, bound)

    # Read the envelope at p + b / 2a: the segment is the number of breakpoints z[1..] below
    # it. One searchsorted over all lines, each line's breakpoints clipped to its query range
    # and offset so that the concatenation stays sorted.
    query = positions[None, :] + (b / two_a)[:, None]
    lo, hi = query[:, :1] - 1.0, query[:, -1:] + 1.0
    span = float((hi - lo).max()) + 1.0
    offset = (np.arange(lines, dtype=np.float64) * span)[:, None] - lo
    breaks = np.clip(bound[:, 1:], lo, hi) + offset  # (lines, n), rows in increasing blocks
    segment = np.searchsorted(breaks.ravel(), (query + offset).ravel(), side="left")
    segment = segment.reshape(lines, n) - (np.arange(lines) * n)[:, None]
    arg = np.take_along_axis(vertex, segment, axis=1)
    t = positions[None, :] - arg
    out = np.take_along_axis(f, arg, axis=1) - (a[:, None] * t * t + b[:, None] * t)
    return out, arg


def distance_transform(
    values: np.ndarray, deformation: object
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact 2-D generalized distance transform (unbounded displacements), linear time.

    ``D[k, y, x] = max_{y', x'} f[k, y', x'] - (a_x dx^2 + b_x dx + a_y dy^2 + b_y dy)`` with
    ``dx = x - x'``, ``dy = y - y'`` (Felzenszwalb et al., PAMI 2010, eq. 4; ``dt.cc``).

    Parameters
    ----------
    values:
        ``(K, H, W)`` or ``(H, W)`` scores (``-inf`` where a filter does not fit).
    deformation:
        ``(4,)`` or ``(K, 4)`` weights ``a_x, b_x, a_y, b_y``.

    Returns
    -------
    out : np.ndarray
        Same shape as ``values``, float64.
    ix, iy : np.ndarray
        int64 column and row of the maximising placement of each output.
    """
    f = np.asarray(values, dtype=np.float64)
    single = f.ndim == 2
    if single:
        f = f[None]
    if f.ndim != 3:
        raise ValueError(f"values must have shape (H, W) or (K, H, W), got {np.shape(values)}")
    count, height, width = f.shape
    w = _weights(deformation, count)
    # Pass along y: lines are the columns of every map.
    cols = f.transpose(0, 2, 1).reshape(count * width, height)
    tmp, arg_y = distance_transform_1d(cols, np.repeat(w[:, 2], width), np.repeat(w[:, 3], width))
    tmp = tmp.reshape(count, width, height).transpose(0, 2, 1)
    arg_y = arg_y.reshape(count, width, height).transpose(0, 2, 1)
    # Pass along x on the result: lines are the rows.
    out, ix = distance_transform_1d(
        tmp.reshape(count * height, width),
        np.repeat(w[:, 0], height),
        np.repeat(w[:, 1], height),
    )
    out = out.reshape(count, height, width)
    ix = ix.reshape(count, height, width)
    iy = np.take_along_axis(arg_y, ix, axis=2)
    if single:
        return out[0], ix[0], iy[0]
    return out, ix, iy


def _bounded_pass(
    f: np.ndarray, a: np.ndarray, b: np.ndarray, window: int, start: int, step: int, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Bounded 1-D transform along axis 1 of ``(K, n, m)``, outputs ``start + step t``."""
    kk, n, m = f.shape
    last = start + step * (count - 1)
    lo = min(0, start - window)  # index range of placements the outputs can reach
    hi = max(n, last + window + 1)
    padded = np.full((kk, hi - lo, m), -np.inf, dtype=f.dtype)
    padded[:, -lo : n - lo] = f
    best = np.full((kk, count, m), -np.inf, dtype=f.dtype)
    arg = np.zeros((kk, count, m), dtype=np.int64)
    outputs = start + step * np.arange(count)
    candidate = np.empty_like(best)
    better = np.empty(best.shape, dtype=bool)
    # Placements j = i - t in increasing order (t from +window down), strict '>' keeps the
    # first maximum, as bounded_dt.cc does.
    for t in range(window, -window - 1, -1):
        first = start - t - lo
        source = padded[:, first : first + step * (count - 1) + 1 : step]
        cost = (a * t * t + b * t).astype(f.dtype)[:, None, None]
        np.subtract(source, cost, out=candidate)
        np.greater(candidate, best, out=better)
        np.maximum(best, candidate, out=best)
        np.copyto(arg, (outputs - t)[None, :, None], where=better)
    return best, arg


def bounded_distance_transform(
    values: np.ndarray,
    deformation: object,
    window: int = 4,
    rows: tuple[int, int, int] | None = None,
    cols: tuple[int, int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """voc-release5 ``bounded_dt``: the transform over displacements of at most ``window`` cells.

    Parameters
    ----------
    values:
        ``(K, H, W)`` or ``(H, W)`` scores.
    deformation:
        ``(4,)`` or ``(K, 4)`` weights ``a_x, b_x, a_y, b_y``.
    window:
        Largest displacement ``s`` along each axis (release 5: 4 cells, a 9x9 window).
    rows, cols:
        ``(start, step, count)``: compute only the outputs at rows ``start + step i``
        (``i < count``) and likewise columns; default every row/column. Placements may lie
        anywhere in ``values``.

    Returns
    -------
    out : np.ndarray
        ``(K, count_rows, count_cols)`` (or 2-D), float32 for float32 input, else float64
        (voc-release5 scores in double; float32 keeps ~7 significant digits of scores that
        are sums of a few dozen terms of order 1).
    ix, iy : np.ndarray
        int64 column and row (indices into ``values``) of the maximising placement.
    """
    f = np.asarray(values)
    if f.dtype not in (np.float32, np.float64):
        f = f.astype(np.float64)
    single = f.ndim == 2
    if single:
        f = f[None]
    if f.ndim != 3:
        raise ValueError(f"values must have shape (H, W) or (K, H, W), got {np.shape(values)}")
    if not is_int(window) or window < 0:
        raise ValueError(f"window must be a non-negative int, got {window!r}")
    count, height, width = f.shape
    w = _weights(deformation, count)
    rows = rows if rows is not None else (0, 1, height)
    cols = cols if cols is not None else (0, 1, width)
    tmp, arg_y = _bounded_pass(f, w[:, 2], w[:, 3], int(window), *rows)
    out, ix = _bounded_pass(tmp.transpose(0, 2, 1), w[:, 0], w[:, 1], int(window), *cols)
    out, ix = out.transpose(0, 2, 1), ix.transpose(0, 2, 1)
    iy = np.take_along_axis(arg_y, ix, axis=2)
    if single:
        return out[0], ix[0], iy[0]
    return out, ix, iy
