"""Star-model scores on one pyramid level, with the argmax placement of every filter.

For a component with root filter ``F_0``, parts ``F_i`` anchored at ``v_i = (ax_i, ay_i)`` on the
level ``interval`` below (twice the resolution) and deformation weights ``d_i``, the score of a
root at ``p_0 = (x, y)`` on level ``l`` is (Felzenszwalb et al., PAMI 2010, eq. 2 and 5;
voc-release5 ``gdetect_dp.m``)

    score(p_0) = b + w_loc . loc(l) + sum_{i >= 0} [ D_i(2^ds_i p_0 + v_i - (2^ds_i - 1) pad)
                                                     + b_i + w_loc_i . loc(l_i) ]

where ``D_i`` is the distance transform (:mod:`.distance_transform`) of the response of ``F_i``
on its level ``l_i = l - interval ds_i``, ``b`` and ``b_i`` the rule offsets times the feature
bias, ``loc`` the octave indicator of ``loc_feat.m``, and ``pad = model.maxsize`` the padding of
every level (the ``(2^ds - 1) pad`` term is voc-release5's "virtual padding" aligning a level's
padding with the padding of the level at half the resolution). The root has a deformation rule
too (weights ``1000``: it does not move). A mixture takes the maximum over its components.

Positions are indices into the padded feature maps. Only the root positions asked for are
scored, and only the filter responses those need are computed (a rectangle per symbol around its
anchors, grown by the deformation window), which is what makes a region of interest cheap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.detection.dpm.distance_transform import (
    bounded_distance_transform,
    distance_transform,
)
from tracking.detection.dpm.model import DpmModel, FilterSymbol
from tracking.detection.dpm.pyramid import PyramidLevel
from tracking.detection.dpm.responses import filter_responses

__all__ = ["LevelRoots", "LevelScores", "root_grid", "root_rectangle", "score_level"]


@dataclass(frozen=True, slots=True)
class LevelScores:
    """Scores of every root position of a rectangle of one pyramid level.

    Attributes
    ----------
    level:
        The root level.
    origin:
        ``(row, col)`` of grid element ``[0, 0]`` in the level's padded feature map.
    scores:
        ``(ny, nx)`` float64, the mixture's score (max over components); ``-inf`` where no
        component's root fits.
    component:
        ``(ny, nx)`` int, index of the best component.
    component_scores:
        ``(C, ny, nx)`` float64, each component's score.
    placements:
        ``(C, S, ny, nx, 2)`` int32: ``(col, row)`` of each symbol (root first, then parts) of
        each component in its own level's padded map, at the argmax of the deformation;
        ``-1`` for symbols a component does not have.
    """

    level: PyramidLevel
    origin: tuple[int, int]
    scores: np.ndarray
    component: np.ndarray
    component_scores: np.ndarray
    placements: np.ndarray

    @classmethod
    def of_mixture(
        cls,
        level: PyramidLevel,
        origin: tuple[int, int],
        component_scores: np.ndarray,
        placements: np.ndarray,
    ) -> LevelScores:
        """The mixture's scores: the best component at every position."""
        best = component_scores.argmax(axis=0)
        scores = np.take_along_axis(component_scores, best[None], axis=0)[0]
        return cls(level, origin, scores, best, component_scores, placements)

    def roots(self, threshold: float) -> LevelRoots:
        """The positions scoring above ``threshold``, with their component and placements."""
        rows, cols = np.nonzero(self.scores > threshold)
        components = self.component[rows, cols]
        placements = self.placements[components, :, rows, cols]  # (N, S, 2)
        return LevelRoots(
            self.level, self.origin, rows, cols, self.scores[rows, cols], components, placements
        )


@dataclass(frozen=True, slots=True)
class LevelRoots:
    """The roots of one pyramid level that scored above a threshold: what detection keeps.

    The star cascade finds a few hundred roots among a level's tens of thousands of positions;
    this holds just those (dense :class:`LevelScores` filled a frame's levels with tens of MB
    of placements of roots that were pruned).

    Attributes
    ----------
    level, origin:
        As :class:`LevelScores`'s.
    rows, cols:
        ``(N,)`` grid elements of the roots (``origin`` plus these is the padded-map index).
    scores:
        ``(N,)`` float64 mixture scores (the best component's).
    components:
        ``(N,)`` index of the best component.
    placements:
        ``(N, S, 2)`` int ``(col, row)`` of each symbol of the root's component, as
        :attr:`LevelScores.placements`; ``-1`` for symbols it does not have.
    """

    level: PyramidLevel
    origin: tuple[int, int]
    rows: np.ndarray
    cols: np.ndarray
    scores: np.ndarray
    components: np.ndarray
    placements: np.ndarray

    @classmethod
    def of_mixture(
        cls,
        level: PyramidLevel,
        origin: tuple[int, int],
        rows: np.ndarray,
        cols: np.ndarray,
        scores: np.ndarray,
        components: np.ndarray,
        placements: np.ndarray,
    ) -> LevelRoots:
        """Roots found by each component, the best component kept where several found the
        same position (ties to the first component, as :meth:`LevelScores.of_mixture`)."""
        if rows.size:
            key = rows.astype(np.int64) * (int(cols.max()) + 1) + cols
            order = np.lexsort((components, -scores, key))
            _, first = np.unique(key[order], return_index=True)
            keep = order[first]
            rows, cols, scores = rows[keep], cols[keep], scores[keep]
            components, placements = components[keep], placements[keep]
        return cls(level, origin, rows, cols, scores, components, placements)


def root_rectangle(
    model: DpmModel,
    shape: tuple[int, ...],
    rows: tuple[int, int] | None,
    cols: tuple[int, int] | None,
) -> tuple[tuple[int, int], tuple[int, int]] | None:
    """The requested root positions of a padded level (default all); ``None`` when empty."""
    grid = root_grid(model, shape)
    rows = rows if rows is not None else (0, grid[0])
    cols = cols if cols is not None else (0, grid[1])
    if rows[1] <= rows[0] or cols[1] <= cols[0]:
        return None
    return rows, cols


def root_grid(model: DpmModel, shape: tuple[int, ...]) -> tuple[int, int]:
    """Number of root positions ``(rows, cols)`` on a padded level of ``shape``."""
    min_h = min(c.root.size[0] for c in model.components)
    min_w = min(c.root.size[1] for c in model.components)
    return max(shape[0] - min_h + 1, 0), max(shape[1] - min_w + 1, 0)


def _anchor_groups(origins: np.ndarray, rect_h: int, rect_w: int) -> list[list[int]]:
    """Symbols whose rectangles overlap enough to share one response computation.

    All rectangles have the same size; a group's responses are computed on the union of its
    rectangles, so symbols join a group (in order of their top edge) while the union stays
    within 1.5 times one rectangle. On a whole frame every part lands in one group; on a
    region of interest, anchors far apart (head and feet) get their own.
    """
    order = np.lexsort((origins[:, 1], origins[:, 0]))
    groups: list[list[int]] = []
    for j in order:
        if groups:
            members = [*groups[-1], int(j)]
            h = origins[members, 0].max() - origins[members, 0].min() + rect_h
            w = origins[members, 1].max() - origins[members, 1].min() + rect_w
            if h * w <= 1.5 * rect_h * rect_w:
                groups[-1].append(int(j))
                continue
        groups.append([int(j)])
    return groups


def _symbol_tables(
    features: np.ndarray,
    symbols: list[FilterSymbol],
    offsets: np.ndarray,
    step: int,
    count: tuple[int, int],
    window: int | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deformation-transformed responses of ``symbols`` read at their anchors.

    ``offsets[j] = (row, col)`` is the table position (anchor) of symbol ``j`` for root grid
    element ``[0, 0]``; grid element ``[i, k]`` reads ``offsets[j] + step (i, k)``. As in
    voc-release5, an anchor outside the symbol's response map (a root hanging far out of the
    padded image) gives ``-inf``.

    Returns values ``(J, ny, nx)`` and placements ``px, py`` (table coordinates).
    """
    ny, nx = count
    height, width = features.shape[:2]
    weights = np.array(
        [s.deformation if s.deformation is not None else (1.0, 0.0, 1.0, 0.0) for s in symbols]
    )
    rigid = np.array([s.deformation is None for s in symbols])
    rows_idx = offsets[:, 0, None] + step * np.arange(ny)[None, :]  # (J, ny) anchors
    cols_idx = offsets[:, 1, None] + step * np.arange(nx)[None, :]  # (J, nx)
    last_row = np.array([height - s.size[0] for s in symbols])[:, None]
    last_col = np.array([width - s.size[1] for s in symbols])[:, None]
    inside = ((rows_idx >= 0) & (rows_idx <= last_row))[:, :, None] & (
        (cols_idx >= 0) & (cols_idx <= last_col)
    )[:, None, :]

    if window is not None:
        # the rectangle each symbol's anchors and displacements span, same size for all
        reach = int(window)
        rect_h, rect_w = step * (ny - 1) + 2 * reach + 1, step * (nx - 1) + 2 * reach + 1
        origins = offsets - reach
        stack = np.empty((len(symbols), rect_h, rect_w), dtype=np.float32)
        for group in _anchor_groups(origins, rect_h, rect_w):
            rows = (int(origins[group, 0].min()), int(origins[group, 0].max()) + rect_h)
            cols = (int(origins[group, 1].min()), int(origins[group, 1].max()) + rect_w)
            maps = filter_responses(features, [symbols[m].weights for m in group], rows, cols)
            for member, response in zip(group, maps, strict=True):
                top, left = origins[member, 0] - rows[0], origins[member, 1] - cols[0]
                stack[member] = response[top : top + rect_h, left : left + rect_w]
        out, ix, iy = bounded_distance_transform(
            stack, weights, reach, rows=(reach, step, ny), cols=(reach, step, nx)
        )
        px = ix + origins[:, 1, None, None]
        py = iy + origins[:, 0, None, None]
        for j in np.flatnonzero(rigid):  # a rigid symbol reads its response at the anchor
            out[j] = stack[j, reach::step, reach::step][:ny, :nx]
            py[j], px[j] = np.meshgrid(rows_idx[j], cols_idx[j], indexing="ij")
    else:
        # Unbounded: the exact transform of every response map, read at the anchors.
        responses = np.stack(filter_responses(features, [s.weights for s in symbols]))
        full, ix_full, iy_full = distance_transform(responses, weights)
        grid_h, grid_w = full.shape[1:]
        r = np.clip(rows_idx, 0, max(grid_h - 1, 0))[:, :, None]
        c = np.clip(cols_idx, 0, max(grid_w - 1, 0))[:, None, :]
        every = np.arange(len(symbols))[:, None, None]
        out, px, py = full[every, r, c], ix_full[every, r, c], iy_full[every, r, c]
        for k in np.flatnonzero(rigid):
            out[k] = responses[k][r[k], c[k]]
            py[k], px[k] = np.broadcast_to(r[k], out[k].shape), np.broadcast_to(c[k], out[k].shape)
    out = np.where(inside, out, -np.inf)
    return out, px, py


def score_level(
    model: DpmModel,
    features: dict[int, np.ndarray],
    level: PyramidLevel,
    pad: tuple[int, int],
    rows: tuple[int, int] | None = None,
    cols: tuple[int, int] | None = None,
    window: int | None = 4,
) -> LevelScores | None:
    """Score the root positions ``rows x cols`` of ``level`` with every component.

    Parameters
    ----------
    model:
        The mixture of star models.
    features:
        Padded feature maps by level index; must hold ``level.index`` and, for models with
        parts, ``level.index - level.interval``.
    level:
        The root level (``level.index >= level.interval`` when the model has parts).
    pad:
        ``(pad_y, pad_x)`` the maps were padded with (:func:`.pyramid.level_features`).
    rows, cols:
        Half-open ranges of root positions (padded-map indices); default all.
    window:
        Largest part displacement in cells (voc-release5's ``bounded_dt``: 4); ``None`` for the
        exact unbounded transform.

    Returns
    -------
    LevelScores or None
        ``None`` when the requested rectangle is empty.
    """
    root_features = features[level.index]
    rectangle = root_rectangle(model, root_features.shape, rows, cols)
    if rectangle is None:
        return None
    rows, cols = rectangle
    ny, nx = rows[1] - rows[0], cols[1] - cols[0]
    pad_y, pad_x = pad
    components = model.components
    n_symbols = max(len(c.symbols) for c in components)
    values = np.full((len(components), n_symbols, ny, nx), -np.inf)
    placements = np.full((len(components), n_symbols, ny, nx, 2), -1, dtype=np.int32)

    by_scale: dict[int, list[tuple[int, int, FilterSymbol]]] = {}
    for ci, component in enumerate(components):
        for j, symbol in enumerate(component.symbols):
            by_scale.setdefault(symbol.anchor[2], []).append((ci, j, symbol))
    for ds, members in by_scale.items():
        step = 2**ds
        table_level = level.index - level.interval * ds
        if table_level not in features:
            raise ValueError(f"features of level {table_level} are needed for level {level.index}")
        symbols = [m[2] for m in members]
        # table position of grid element [0, 0]: step * p + anchor - (step - 1) * pad
        offsets = np.array(
            [
                (
                    step * rows[0] + s.anchor[1] - (step - 1) * pad_y,
                    step * cols[0] + s.anchor[0] - (step - 1) * pad_x,
                )
                for s in symbols
            ]
        )
        out, px, py = _symbol_tables(
            features[table_level], symbols, offsets, step, (ny, nx), window
        )
        octave = min(max(table_level, 0) // level.interval, 2)
        for (ci, j, symbol), o, x, y in zip(members, out, px, py, strict=True):
            values[ci, j] = o + (symbol.bias + symbol.location[octave])
            placements[ci, j, ..., 0] = x
            placements[ci, j, ..., 1] = y

    component_scores = np.empty((len(components), ny, nx))
    for ci, component in enumerate(components):
        total = component.bias + component.location[level.octave]
        component_scores[ci] = total + values[ci, : len(component.symbols)].sum(axis=0)
        # a component whose root does not fit at a position does not score there
        h, w = component.root.size
        fits_r = rows[0] + np.arange(ny) <= root_features.shape[0] - h
        fits_c = cols[0] + np.arange(nx) <= root_features.shape[1] - w
        component_scores[ci][~(fits_r[:, None] & fits_c[None, :])] = -np.inf
    return LevelScores.of_mixture(level, (rows[0], cols[0]), component_scores, placements)
