"""From star-model scores to boxes: detection windows, filter boxes, regression, clipping.

Geometry (voc-release5 ``get_detection_trees.cc``, in 0-based continuous pixel coordinates): a
symbol at padded-map position ``(x, y)`` of a level whose cells cover ``c`` image pixels has the
box ``((x - pad_x) c, (y - pad_y) c, w c, h c)`` for a filter of ``h x w`` cells; the detection
window of a root at ``(x, y)`` is ``((x - shift_x - pad_x) c, (y - shift_y - pad_y) c,
window_w c, window_h c)``; a part on the level of twice the resolution has cells of ``c / 2``.
Boxes of a level computed on a crop of the frame are offset by the crop's corner.

Post-processing follows voc-release5's test pipeline (``pascal_test.m``, ``bboxpred_rescore.m``):
clip to the image (``clipboxes.m``), non-maximum suppression, bounding-box regression from the
filter centres (``bboxpred_get.m``, ``bboxpred_input.m``), clip, suppression again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.detection.dpm.model import DpmModel
from tracking.detection.dpm.scoring import LevelRoots, LevelScores
from tracking.detection.nms import NmsCriterion, nms
from tracking.detection.regions import centres_inside, clip_boxes
from tracking.types import Box

__all__ = [
    "Candidates",
    "candidates",
    "postprocess",
    "predict_boxes",
    "root_windows",
]


@dataclass(frozen=True, slots=True)
class Candidates:
    """Detections before suppression.

    Attributes
    ----------
    windows:
        ``(N, 4)`` detection windows (or predicted boxes) ``x, y, w, h``.
    filters:
        ``(N, S, 4)`` filter boxes, root first, in the component's symbol order; NaN for
        symbols the component does not have.
    scores:
        ``(N,)`` raw scores.
    components:
        ``(N,)`` component index.
    """

    windows: np.ndarray
    filters: np.ndarray
    scores: np.ndarray
    components: np.ndarray

    def take(self, index: np.ndarray) -> Candidates:
        return Candidates(
            self.windows[index], self.filters[index], self.scores[index], self.components[index]
        )

    def with_windows(self, windows: np.ndarray, keep: np.ndarray) -> Candidates:
        return Candidates(windows, self.filters[keep], self.scores[keep], self.components[keep])


def _empty(n_symbols: int) -> Candidates:
    return Candidates(
        np.zeros((0, 4)), np.zeros((0, n_symbols, 4)), np.zeros(0), np.zeros(0, dtype=int)
    )


def root_windows(
    model: DpmModel,
    ls: LevelRoots | LevelScores,
    ys: np.ndarray,
    xs: np.ndarray,
    components: np.ndarray,
    pad: tuple[int, int],
    corner: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """``(N, 4)`` detection windows of the roots at grid elements ``(ys, xs)`` of ``ls``.

    ``components`` holds each root's component; ``corner`` is the ``(x, y)`` of the image the
    level was computed on in the frame.
    """
    return _windows(model, ys, xs, components, pad, ls.level.cell, ls.origin, corner)


def _windows(
    model: DpmModel,
    ys: np.ndarray,
    xs: np.ndarray,
    components: np.ndarray,
    pad: tuple[int, int],
    cell: float | np.ndarray,
    origin: tuple[int, int] | np.ndarray,
    corner: tuple[float, float] | np.ndarray,
) -> np.ndarray:
    """:func:`root_windows` with the level's ``cell``, ``origin`` ``(row, col)`` and ``corner``
    ``(x, y)`` given per root (arrays of N, ``(N, 2)``) or for all (scalars, pairs)."""
    windows_cells = np.array([c.window for c in model.components])  # (C, 2) h, w
    shifts = np.array([c.shift for c in model.components])
    origin, corner = np.asarray(origin), np.asarray(corner)
    x0 = corner[..., 0] + (origin[..., 1] + xs - shifts[components, 1] - pad[1]) * cell
    y0 = corner[..., 1] + (origin[..., 0] + ys - shifts[components, 0] - pad[0]) * cell
    return np.column_stack(
        [x0, y0, windows_cells[components, 1] * cell, windows_cells[components, 0] * cell]
    )


def candidates(
    model: DpmModel,
    scored: list[tuple[LevelRoots, tuple[int, int]]],
    pad: tuple[int, int],
    threshold: float,
    region: Box | None = None,
    limit: int | None = None,
) -> Candidates:
    """Every root position scoring above ``threshold``, as windows and filter boxes.

    Parameters
    ----------
    model:
        The model the scores come from.
    scored:
        ``(roots of a level, (x, y) corner of the image the level was computed on)``.
    pad:
        ``(pad_y, pad_x)`` of the feature maps.
    threshold:
        Strict lower bound on the score.
    region:
        Keep only windows whose centre lies in this region.
    limit:
        Keep at most this many, best scores first.
    """
    pad_y, pad_x = pad
    n_symbols = max(len(c.symbols) for c in model.components)
    kept = [(ls, corner, np.flatnonzero(ls.scores > threshold)) for ls, corner in scored]
    kept = [(ls, corner, above) for ls, corner, above in kept if above.size]
    if not kept:
        return _empty(n_symbols)
    # The roots of every level in one set of arrays, each root with its level's geometry: a
    # region's few roots per level made the per-level numpy calls most of the time here.
    ys, xs, comp, scores, placements = (
        np.concatenate([getattr(ls, name)[above] for ls, _, above in kept])
        for name in ("rows", "cols", "components", "scores", "placements")
    )
    counts = [above.size for _, _, above in kept]
    cell = np.repeat([ls.level.cell for ls, _, _ in kept], counts)
    origin = np.repeat([ls.origin for ls, _, _ in kept], counts, axis=0)
    corner = np.repeat([corner for _, corner, _ in kept], counts, axis=0)  # (N, 2) x, y
    boxes = _windows(model, ys, xs, comp, pad, cell, origin, corner)
    if region is not None:
        inside = centres_inside(boxes, region)
        comp, boxes, scores, placements, cell, corner = (
            a[inside] for a in (comp, boxes, scores, placements, cell, corner)
        )
    filters = np.full((comp.size, n_symbols, 4), np.nan)
    for ci, component in enumerate(model.components):
        sel = np.flatnonzero(comp == ci)
        if sel.size == 0:
            continue
        symbols = component.symbols
        # every symbol at once: (n, S, 2) placements (col, row), each symbol's cell size
        place = placements[sel, : len(symbols)]
        scale = np.array([2 ** sym.anchor[2] for sym in symbols])
        c = (cell[sel, None] / scale)[:, :, None]  # (n, S, 1)
        sizes = np.array([sym.size[::-1] for sym in symbols]) * c  # (n, S, 2) w, h in pixels
        filters[sel, : len(symbols), :2] = (place - (pad_x, pad_y)) * c + corner[sel, None]
        filters[sel, : len(symbols), 2:] = sizes
    merged = Candidates(boxes, filters, scores, comp)
    if limit is not None and merged.scores.size > limit:
        merged = merged.take(np.argsort(-merged.scores, kind="stable")[:limit])
    return merged


def predict_boxes(model: DpmModel, c: Candidates) -> np.ndarray:
    """``bboxpred_get.m``: boxes regressed from the window and the filter centres.

    In MATLAB's inclusive 1-based pixels (``x1 = x + 1``, ``x2 = x + w``): with the window's
    width ``w = x2 - x1``, height ``h`` and centre ``(rx, ry)``, and filter centres
    ``(px_j, py_j)`` in ``model.filters`` order, the features are
    ``A = [(px_j - rx) / w, (py_j - ry) / h, ..., 1]`` and the box is
    ``x1 + w A b_x1, y1 + h A b_y1, x2 + w A b_x2, y2 + h A b_y2``.
    """
    out = c.windows.copy()
    for ci, component in enumerate(model.components):
        coefficients = component.bbox_regression
        sel = np.flatnonzero(c.components == ci)
        if coefficients is None or sel.size == 0:
            continue
        win = c.windows[sel]
        x1, y1 = win[:, 0] + 1, win[:, 1] + 1
        x2, y2 = win[:, 0] + win[:, 2], win[:, 1] + win[:, 3]
        w, h = x2 - x1, y2 - y1
        rx, ry = x1 + w / 2, y1 + h / 2
        # reduceboxes.m keeps the component's filter boxes in model.filters order
        order = np.argsort([s.filter_index for s in component.symbols], kind="stable")
        f = c.filters[sel][:, order]
        px = (f[..., 0] + 1) + (f[..., 2] - 1) / 2
        py = (f[..., 1] + 1) + (f[..., 3] - 1) / 2
        features = np.empty((sel.size, 2 * order.size + 1))
        features[:, 0:-1:2] = (px - rx[:, None]) / w[:, None]
        features[:, 1:-1:2] = (py - ry[:, None]) / h[:, None]
        features[:, -1] = 1.0
        d = features @ coefficients.T  # (n, 4): displacements of x1, y1, x2, y2
        nx1, ny1 = x1 + w * d[:, 0], y1 + h * d[:, 1]
        nx2, ny2 = x2 + w * d[:, 2], y2 + h * d[:, 3]
        out[sel] = np.column_stack([nx1 - 1, ny1 - 1, nx2 - nx1 + 1, ny2 - ny1 + 1])
    return out


def postprocess(
    model: DpmModel,
    c: Candidates,
    shape: tuple[int, ...],
    overlap: float,
    regression: bool,
    criterion: NmsCriterion = "smaller",
) -> Candidates:
    """Clip, suppress, regress, clip, suppress (``pascal_test.m`` + ``bboxpred_rescore.m``)."""
    c = c.with_windows(*clip_boxes(c.windows, shape))
    c = c.take(nms(c.windows, c.scores, overlap, criterion))
    if regression and c.scores.size:
        c = c.with_windows(*clip_boxes(predict_boxes(model, c), shape))
        c = c.take(nms(c.windows, c.scores, overlap, criterion))
    return c
