"""Compiled star-model kernels: exact dense scoring and the star cascade's per-root search.

Both score the roots of one mixture component on one pyramid level, with the filters laid out
by :func:`kernel_filters` (the cells and channels of a filter row flattened, so each row is one
contiguous dot product that the compiler vectorises). :func:`.cascade.cascade_level` prepares
their inputs and reads their outputs.

* :func:`exact_component` scores every root of a rectangle exactly: it computes the part
  responses densely on the block of placements the roots' anchors reach, four positions per
  pass, and runs the bounded distance transform as a y pass and an x pass (as
  :func:`.distance_transform.bounded_distance_transform`, first maximum kept).
* :func:`cascade_roots` is the star cascade (:mod:`.cascade`): a per-root, data-dependent loop
  that numpy cannot vectorise. Part responses are computed lazily, once per position and part
  (a cache per level; a missing one with the rest of its aligned block of four columns, which
  cost little more together), and a part's placements are visited cheapest first, so the
  deformation margin ends the search.

The kernels run single-threaded and release the GIL: the detector scores levels in threads.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np

from tracking.detection.dpm.model import DpmModel

if TYPE_CHECKING:
    from tracking.detection.dpm.cascade import PcaProjection

__all__ = [
    "KernelFilters",
    "cascade_roots",
    "exact_component",
    "flat",
    "kernel_filters",
    "kernels_apply",
    "project_cells",
]


@numba.njit(cache=True, nogil=True, fastmath=True)
def _dot(features, row, col, weights, channels):  # pragma: no cover - compiled
    """One filter response: ``sum weights[dy, dx, c] features[row + dy, col + dx, c]``.

    ``features`` is ``(H, W C)`` and ``weights`` ``(h, w C)`` (the cells and channels of a row
    flattened), so each filter row is one contiguous dot product that the compiler
    vectorises (with ``C = 6`` a per-cell loop is too short for that).
    """
    h, row_length = weights.shape
    start = col * channels
    total = np.float32(0.0)
    for dy in range(h):
        # 1-D slices: with them the compiler vectorises the loop (2x faster than 2-D indexing)
        line = features[row + dy, start : start + row_length]
        taps = weights[dy]
        for i in range(row_length):
            total += taps[i] * line[i]
    return total


@numba.njit(cache=True, nogil=True, fastmath=True)
def _dot4(features, row, col, weights, channels):  # pragma: no cover - compiled
    """The responses at ``(row, col + i)``, ``i < 4``, as :func:`_dot` computes each.

    Each filter tap is loaded once for the four positions and the four sums are independent
    chains: about 3x faster than four :func:`_dot` calls. Needs ``col + 3`` in the map.
    """
    h, row_length = weights.shape
    start = col * channels
    a0 = a1 = a2 = a3 = np.float32(0.0)
    for dy in range(h):
        # one 1-D slice per position, indexed from 0: with ``i + channels`` indices the
        # compiler must allow for negative ones and does not vectorise (15x slower)
        line = features[row + dy]
        l0 = line[start : start + row_length]
        l1 = line[start + channels : start + channels + row_length]
        l2 = line[start + 2 * channels : start + 2 * channels + row_length]
        l3 = line[start + 3 * channels : start + 3 * channels + row_length]
        taps = weights[dy]
        for i in range(row_length):
            w = taps[i]
            a0 += w * l0[i]
            a1 += w * l1[i]
            a2 += w * l2[i]
            a3 += w * l3[i]
    return a0, a1, a2, a3


@numba.njit(cache=True, nogil=True, fastmath=True)
def project_cells(cells, directions, out):  # pragma: no cover - compiled
    """``out[i, j] = cells[i] . directions[j]``: ``(N, C)`` cells on ``(k, C)`` directions.

    The cascade's projection (:meth:`.cascade.PcaProjection.project`), compiled rather than
    a BLAS product: OpenBLAS's threads spin after every call and, next to the detector's level
    threads, took a core from them (the DPM ran at half speed unless ``OPENBLAS_NUM_THREADS``
    was 1); single-threaded, this loop is as fast as BLAS's.
    """
    n, channels = cells.shape
    k = directions.shape[0]
    for i in range(n):
        cell = cells[i]
        for j in range(k):
            direction = directions[j]
            total = np.float32(0.0)
            for c in range(channels):
                total += cell[c] * direction[c]
            out[i, j] = total


@numba.njit(cache=True, nogil=True)
def _responses(features, weights, channels, row0, col0, out):  # pragma: no cover - compiled
    """``out[y, x] = _dot(features, row0 + y, col0 + x, weights, channels)`` for all of ``out``,
    four columns at a time (:func:`_dot4`)."""
    rows, cols = out.shape
    for y in range(rows):
        line_out = out[y]
        x = 0
        while x + 4 <= cols:
            a0, a1, a2, a3 = _dot4(features, row0 + y, col0 + x, weights, channels)
            line_out[x], line_out[x + 1], line_out[x + 2], line_out[x + 3] = a0, a1, a2, a3
            x += 4
        for rest in range(x, cols):
            line_out[rest] = _dot(features, row0 + y, col0 + rest, weights, channels)


@numba.njit(cache=True, nogil=True)
def exact_component(
    start, root_features, root_weights, root_offset, part_features, parts, channels, anchors,
    steps, deformations, window, threshold,
):  # pragma: no cover - compiled  # fmt: skip
    """Exact scores and placements of every root of one component on a rectangle of a level.

    What :func:`cascade_roots` computes with no pruning, done densely: the root response on the
    grid, then per part its response on the block of placements the grid's anchors reach and
    the bounded distance transform (voc-release5 ``bounded_dt``, eq. 5 of Felzenszwalb et al.
    2010) as two 1-D passes, along y then x, each keeping its first maximum. ``start``
    (``(ny, nx)``, -inf where the root does not fit) holds the constant terms; arguments as
    :func:`cascade_roots`'s. Returns ``(scores (ny, nx) float64, -inf at or below threshold,
    placements (P, ny, nx, 2) (col, row))``.
    """
    ny, nx = start.shape
    n_parts = parts.shape[0]
    scores = np.full((ny, nx), -np.inf)
    placements = np.full((n_parts, ny, nx, 2), -1, dtype=np.int64)
    root = np.empty((ny, nx), dtype=np.float32)
    _responses(root_features, root_weights, channels, root_offset[0], root_offset[1], root)
    for y in range(ny):
        for x in range(nx):
            if start[y, x] != -np.inf:
                scores[y, x] = np.float64(start[y, x]) + root[y, x]
    last_row = part_features.shape[0] - parts.shape[1]
    last_col = part_features.shape[1] // channels - parts.shape[2] // channels
    for p in range(n_parts):
        step, ar0, ac0 = steps[p], anchors[p, 0], anchors[p, 1]
        ax, bx, ay, by = (
            deformations[p, 0],
            deformations[p, 1],
            deformations[p, 2],
            deformations[p, 3],
        )
        r_lo, r_hi = max(ar0 - window, 0), min(ar0 + step * (ny - 1) + window, last_row)
        c_lo, c_hi = max(ac0 - window, 0), min(ac0 + step * (nx - 1) + window, last_col)
        if r_hi < r_lo or c_hi < c_lo:
            scores[:] = -np.inf
            break
        block = np.empty((r_hi - r_lo + 1, c_hi - c_lo + 1), dtype=np.float32)
        _responses(part_features, parts[p], channels, r_lo, c_lo, block)
        nc = block.shape[1]
        # pass along y at the anchor rows (t = anchor - placement, placements ascending)
        best_y = np.full((ny, nc), -np.inf)
        arg_y = np.zeros((ny, nc), dtype=np.int64)
        for y in range(ny):
            ar = ar0 + step * y
            for t in range(window, -window - 1, -1):
                row = ar - t
                if row < r_lo or row > r_hi:
                    continue
                cost = ay * t * t + by * t
                line = block[row - r_lo]
                for j in range(nc):
                    value = line[j] - cost
                    if value > best_y[y, j]:
                        best_y[y, j] = value
                        arg_y[y, j] = row
        # pass along x at the anchor columns
        for y in range(ny):
            ar = ar0 + step * y
            for x in range(nx):
                ac = ac0 + step * x
                if scores[y, x] == -np.inf:
                    continue
                if ar < 0 or ar > last_row or ac < 0 or ac > last_col:
                    scores[y, x] = -np.inf  # as scoring: an anchor off the map scores -inf
                    continue
                best, best_col = -np.inf, -1
                for u in range(window, -window - 1, -1):
                    col = ac - u
                    if col < c_lo or col > c_hi:
                        continue
                    value = best_y[y, col - c_lo] - (ax * u * u + bx * u)
                    if value > best:
                        best, best_col = value, col
                scores[y, x] += best
                if best_col >= 0:
                    placements[p, y, x, 0] = best_col
                    placements[p, y, x, 1] = arg_y[y, best_col - c_lo]
    for y in range(ny):
        for x in range(nx):
            if not scores[y, x] > threshold:
                scores[y, x] = -np.inf
                placements[:, y, x] = -1
    return scores, placements


@numba.njit(cache=True, nogil=True)
def _placement_order(deformations, window):  # pragma: no cover - compiled
    """Per part, the ``(2 window + 1)^2`` displacements ``(t, u)`` (anchor minus placement,
    rows and columns) sorted by deformation cost, cheapest first, and their costs.

    Returns int64 ``(P, n)`` ``ts`` and ``us`` and float64 ``(P, n)`` costs. A stable sort of
    the displacements listed by ascending placement, so equal costs keep that order.
    """
    side = 2 * window + 1
    n_parts = deformations.shape[0]
    ts = np.empty((n_parts, side * side), dtype=np.int64)
    us = np.empty((n_parts, side * side), dtype=np.int64)
    costs = np.empty((n_parts, side * side))
    raw = np.empty(side * side)
    for p in range(n_parts):
        ax, bx, ay, by = (
            deformations[p, 0],
            deformations[p, 1],
            deformations[p, 2],
            deformations[p, 3],
        )
        k = 0
        for t in range(window, -window - 1, -1):  # placements ascending
            for u in range(window, -window - 1, -1):
                raw[k] = (ay * t * t + by * t) + ax * u * u + bx * u
                k += 1
        order = np.argsort(raw, kind="mergesort")
        for k in range(side * side):
            ts[p, k] = window - order[k] // side
            us[p, k] = window - order[k] % side
            costs[p, k] = raw[order[k]]
    return ts, us, costs


@numba.njit(cache=True, nogil=True)
def _deformed_part(
    partial, features, weights, channels, cache, done, anchor_row, anchor_col, ts, us, costs,
    prune,
):  # pragma: no cover - compiled  # fmt: skip
    """Best ``response(q) - d(anchor - q)`` over the placements within the window.

    ``features`` and ``weights`` as :func:`_dot` takes them; ``ts``, ``us``, ``costs`` one
    part's row of :func:`_placement_order`. Placements with ``partial - d < prune`` are
    skipped: in order of cost, the first such one ends the search. Responses come from
    ``cache`` where ``done`` says they were computed. Ties go to the first placement in
    (row, column) order, as the dense transform breaks them. Returns ``(value, row, col,
    partial - d at the best placement)``; ``-inf`` when no placement qualifies.
    """
    height = features.shape[0] - weights.shape[0]
    width = (features.shape[1] - weights.shape[1]) // channels
    best, best_row, best_col, best_margin = -np.inf, -1, -1, -np.inf
    for k in range(costs.shape[0]):
        cost = costs[k]
        if partial - cost < prune:
            break
        row, col = anchor_row - ts[k], anchor_col - us[k]
        if row < 0 or row > height or col < 0 or col > width:
            continue
        if not done[row, col]:
            # The four placements of the aligned block: its neighbours are usually wanted
            # too (by this root or the next ones), four cost little more than one, and
            # aligned blocks never overlap, so no response is computed twice.
            base = col - col % 4
            if base + 3 <= width:
                four = _dot4(features, row, base, weights, channels)
                for i in range(4):
                    cache[row, base + i] = four[i]
                    done[row, base + i] = True
            else:
                cache[row, col] = _dot(features, row, col, weights, channels)
                done[row, col] = True
        response = cache[row, col]
        value = response - cost
        if value > best or (
            value == best and (row < best_row or (row == best_row and col < best_col))
        ):
            best, best_row, best_col, best_margin = value, row, col, partial - cost
    return best, best_row, best_col, best_margin


@numba.njit(cache=True, nogil=True)
def cascade_roots(
    start,  # (ny, nx) float32: offsets + approximate root response per root position
    root_approx,  # (ny, nx) float32: the approximate root response alone
    root_features,  # (H, W, 32) exact features of the root level
    root_weights,  # (h, w, 32)
    root_offset,  # (row, col) of root grid element [0, 0] in root_features
    part_features_approx,  # (H2, W2 k)
    part_features,  # (H2, W2 C)
    parts_approx,  # (P, h, w k)
    parts,  # (P, h, w C)
    approx_channels,  # k
    channels,  # C
    anchors,  # (P, 2) int64: part-level (row, col) of the anchor of root grid [0, 0]
    steps,  # (P,) int64: 2^ds
    deformations,  # (P, 4) float64
    window,
    stage,  # (2 + 2P,)
    margin,  # (2 + 2P,)
    threshold,
    cache,  # (2, P, H2, W2) float32: approximate and exact part responses, computed lazily
    done,  # (2, P, H2, W2) bool: which of them are computed
    record,  # bool: keep every stage's partial score and margin (fitting)
):  # pragma: no cover - compiled
    """Roots of one component on one level passing every stage with a score above threshold.

    Features and filters come with the cells and channels of a row flattened (:func:`_dot`).
    Returns ``(rows, cols, scores, placements (N, P, 2) (col, row), stages (N, 2 + 2P),
    margins (N, 2 + 2P))``; stages and margins are filled only with ``record``.
    """
    ny, nx = start.shape
    n_parts = parts.shape[0]
    n_stages = 2 + 2 * n_parts
    part_rows, part_cols = part_features.shape[0], part_features.shape[1] // channels
    capacity = ny * nx
    rows = np.empty(capacity, dtype=np.int64)
    cols = np.empty(capacity, dtype=np.int64)
    scores = np.empty(capacity, dtype=np.float64)
    placements = np.empty((capacity, n_parts, 2), dtype=np.int64)
    kept = capacity if record else 1
    stages = np.full((kept, n_stages), np.nan)
    margins = np.full((kept, n_stages), np.nan)
    here_stages = np.empty(n_stages)
    here_margins = np.full(n_stages, np.nan)
    approx = np.empty(n_parts)
    place = np.empty((n_parts, 2), dtype=np.int64)
    count = 0
    ts, us, costs = _placement_order(deformations, window)
    last_row = part_rows - parts.shape[1]
    last_col = part_cols - parts.shape[2] // channels
    for y in range(ny):
        for x in range(nx):
            s = np.float64(start[y, x])
            if s == -np.inf or not s >= stage[0]:  # -inf: the root does not fit here
                continue
            here_stages[0] = s
            alive = True
            approx[:] = 0.0
            for p in range(n_parts):  # approximate parts
                ar = anchors[p, 0] + steps[p] * y
                ac = anchors[p, 1] + steps[p] * x
                if ar < 0 or ar > last_row or ac < 0 or ac > last_col:
                    alive = False  # as scoring: an anchor off the response map scores -inf
                    break
                value, _, _, m = _deformed_part(
                    s, part_features_approx, parts_approx[p], approx_channels, cache[0, p],
                    done[0, p], ar, ac, ts[p], us[p], costs[p], margin[1 + p],
                )  # fmt: skip
                s += value
                here_stages[1 + p], here_margins[1 + p] = s, m
                approx[p] = value
                if s == -np.inf or not s >= stage[1 + p]:
                    alive = False
                    break
            if not alive:
                continue
            r0, c0 = root_offset[0] + y, root_offset[1] + x
            s += _dot(root_features, r0, c0, root_weights, channels) - root_approx[y, x]
            here_stages[1 + n_parts] = s
            if not s >= stage[1 + n_parts]:
                continue
            for p in range(n_parts):  # exact parts replace the approximate ones
                k = 2 + n_parts + p
                ar = anchors[p, 0] + steps[p] * y
                ac = anchors[p, 1] + steps[p] * x
                rest = s - approx[p]
                value, pr, pc, m = _deformed_part(
                    rest, part_features, parts[p], channels, cache[1, p], done[1, p], ar, ac,
                    ts[p], us[p], costs[p], margin[k],
                )  # fmt: skip
                s = rest + value
                here_stages[k], here_margins[k] = s, m
                place[p, 0], place[p, 1] = pc, pr
                if s == -np.inf or not s >= stage[k]:
                    alive = False
                    break
            if not alive or not s > threshold:
                continue
            rows[count], cols[count], scores[count] = y, x, s
            placements[count] = place
            if record:
                stages[count] = here_stages
                margins[count] = here_margins
            count += 1
    return (
        rows[:count], cols[:count], scores[:count], placements[:count], stages[:count],
        margins[:count],
    )  # fmt: skip


def flat(array: np.ndarray) -> np.ndarray:
    """``(..., W, C)`` -> contiguous ``(..., W C)``: the layout :func:`_dot` reads."""
    return np.ascontiguousarray(array).reshape(*array.shape[:-2], -1)


@dataclass(frozen=True, slots=True)
class KernelFilters:
    """One component's filters in the kernels' layout (:func:`_dot`), made once per model.

    Attributes
    ----------
    root:
        ``(h, w C)`` float32 root filter.
    root_anchor:
        ``(row, col)`` int64 offset of the root filter from its position (the anchor).
    parts:
        ``(P, h, w C)`` float32 part filters (``(0, 1, 1)`` for a component without parts).
    part_anchors:
        ``(P, 2)`` int64: part-level ``(row, col)`` of the anchor of each part of the root at
        position ``(0, 0)`` (voc-release5's virtual padding included).
    deformations:
        ``(P, 4)`` float64 deformation weights.
    steps:
        ``(P,)`` int64: ``2^ds``, part cells per root cell.
    part_levels:
        ``interval`` multiples between the root's level and the parts' (``ds``; 0 without parts).
    approx_parts:
        ``(P, h, w k)`` projected part filters, or a placeholder without a projection.
    """

    root: np.ndarray
    root_anchor: np.ndarray
    parts: np.ndarray
    part_anchors: np.ndarray
    deformations: np.ndarray
    steps: np.ndarray
    part_levels: int
    approx_parts: np.ndarray


def kernels_apply(model: DpmModel) -> bool:
    """Whether the compiled kernels can score ``model``: each component's parts of one size
    and on one level (they stack a component's parts in one array). The voc-release5 person
    models qualify; :func:`.scoring.score_level` scores any model."""
    return all(
        len({(p.size, p.anchor[2]) for p in component.parts}) <= 1 for component in model.components
    )


def kernel_filters(
    model: DpmModel, pad: tuple[int, int], projection: PcaProjection | None = None
) -> tuple[KernelFilters, ...]:
    """Every component's :class:`KernelFilters` for maps padded by ``pad``.

    Raises ``ValueError`` for a model the kernels cannot score (:func:`kernels_apply`).
    """
    if not kernels_apply(model):
        raise ValueError(
            "the compiled kernels need each component's parts of one size on one level"
        )
    out = []
    pad_y, pad_x = pad
    for ci, component in enumerate(model.components):
        ds, step = 0, 1
        anchors = np.zeros((0, 2), dtype=np.int64)
        parts = np.zeros((0, 1, model.num_features), dtype=np.float32)
        deformations = np.zeros((0, 4))
        if component.parts:
            ds = component.parts[0].anchor[2]
            step = 2**ds
            anchors = np.array(
                [
                    (p.anchor[1] - (step - 1) * pad_y, p.anchor[0] - (step - 1) * pad_x)
                    for p in component.parts
                ],
                dtype=np.int64,
            )
            parts = flat(np.stack([p.weights for p in component.parts]))
            deformations = np.array([p.deformation for p in component.parts], dtype=np.float64)
        approx = (
            flat(projection.parts[ci])
            if projection is not None
            else np.zeros((len(component.parts), 1, 1), np.float32)
        )
        out.append(
            KernelFilters(
                root=flat(component.root.weights),
                root_anchor=np.array(component.root.anchor[1::-1], dtype=np.int64),
                parts=parts,
                part_anchors=anchors,
                deformations=deformations,
                steps=np.full(len(component.parts), step, dtype=np.int64),
                part_levels=ds,
                approx_parts=approx,
            )
        )
    return tuple(out)
