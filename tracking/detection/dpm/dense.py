"""Dense score maps for a region of interest, as the particle filter reads them.

One grid per pyramid level and detection-window height: the components of a model whose
windows have the same height (a component and its mirror, or two components of different
widths) share a grid. Grid element ``[i, j]`` is the window centred at
``origin + (j, i) * stride``; each component's scores are moved onto the first member's grid by
the whole number of cells between their window centres (exact for mirrored pairs, within half a
cell otherwise) and the best component wins. ``part_offsets`` holds, for the winning component,
the offset of each part's box centre from the window centre, in pixels, in the detector's part
slots (NaN for a part that component lacks).
"""

from __future__ import annotations

import numpy as np

from tracking.detection.base import DenseScores
from tracking.detection.dpm.model import DpmModel
from tracking.detection.dpm.scoring import LevelScores
from tracking.types import Box

__all__ = ["dense_scores"]


def _shifted(array: np.ndarray, sy: int, sx: int, fill: float) -> np.ndarray:
    """``out[i, j] = array[i - sy, j - sx]``, ``fill`` where that is outside ``array``."""
    if sy == 0 and sx == 0:
        return array
    out = np.full(array.shape, fill, dtype=np.float64)
    h, w = array.shape[:2]
    dst = (slice(max(sy, 0), h + min(sy, 0)), slice(max(sx, 0), w + min(sx, 0)))
    src = (slice(max(-sy, 0), h + min(-sy, 0)), slice(max(-sx, 0), w + min(-sx, 0)))
    out[dst] = array[src]
    return out


def dense_scores(
    model: DpmModel,
    scored: list[tuple[LevelScores, tuple[int, int]]],
    pad: tuple[int, int],
    region: Box,
    part_names: tuple[str, ...],
    slots: tuple[tuple[int, ...], ...],
) -> DenseScores | None:
    """Assemble :class:`DenseScores` from scored levels, keeping centres inside ``region``.

    Parameters
    ----------
    model:
        The model.
    scored:
        ``(scores of a level, (x, y) corner of the image it was computed on)``.
    pad:
        ``(pad_y, pad_x)`` of the feature maps.
    region:
        Region of interest (already clipped to the frame).
    part_names, slots:
        The detector's part names and, per component, the slot of each part
        (:func:`tracking.detection.dpm.parts.model_part_names`).

    Returns
    -------
    DenseScores or None
        ``None`` when no window centre of any level lies in the region.
    """
    pad_y, pad_x = pad
    groups: dict[int, list[int]] = {}
    for ci, comp in enumerate(model.components):
        groups.setdefault(comp.window[0], []).append(ci)
    # per component with parts: each part's cell size in root cells and its box centre
    # from its placement, in its own cells (both per part: (P, 1) for (P, 2) placements)
    part_scale = [
        np.array([[2.0 ** -p.anchor[2]] for p in comp.parts]) for comp in model.components
    ]
    part_half = [
        np.array([[p.size[1] / 2 - pad_x, p.size[0] / 2 - pad_y] for p in comp.parts])
        for comp in model.components
    ]
    heights, grids, origins, strides, offsets = [], [], [], [], []
    for ls, (ox, oy) in scored:
        c = ls.level.cell
        ny, nx = ls.scores.shape
        for window_h, members in groups.items():
            first = model.components[members[0]]
            centre_x = first.window[1] / 2 - first.shift[1]  # window centre in cells from x
            centre_y = first.window[0] / 2 - first.shift[0]
            xs = ox + (ls.origin[1] + np.arange(nx) - pad_x + centre_x) * c
            ys = oy + (ls.origin[0] + np.arange(ny) - pad_y + centre_y) * c
            cols = np.flatnonzero((xs >= region.x) & (xs <= region.x + region.w))
            rows = np.flatnonzero((ys >= region.y) & (ys <= region.y + region.h))
            if rows.size == 0 or cols.size == 0:
                continue
            grid = np.full((ny, nx), -np.inf)
            parts = np.full((ny, nx, len(part_names), 2), np.nan)
            window_centres = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), axis=-1)
            for ci in members:
                comp = model.components[ci]
                # whole cells between this component's window centre and the first member's
                sx = round(comp.window[1] / 2 - comp.shift[1] - centre_x)
                sy = round(comp.window[0] / 2 - comp.shift[0] - centre_y)
                scores = _shifted(ls.component_scores[ci], sy, sx, -np.inf)
                better = scores > grid
                grid = np.where(better, scores, grid)
                if not comp.parts:
                    continue
                # (ny, nx, P, 2) part box centres in pixels, moved onto the first member's grid
                place = ls.placements[ci, 1 : 1 + len(comp.parts)].transpose(1, 2, 0, 3)
                centres = (place + part_half[ci]) * (part_scale[ci] * c) + (ox, oy)
                moved = _shifted(centres, sy, sx, np.nan) - window_centres[:, :, None, :]
                slot = np.array(slots[ci])
                parts[:, :, slot] = np.where(better[..., None, None], moved, parts[:, :, slot])
            sl = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
            heights.append(window_h * c)
            grids.append(grid[sl])
            offsets.append(parts[sl])
            origins.append((xs[cols[0]], ys[rows[0]]))
            strides.append(c)
    if not grids:
        return None
    order = np.argsort(heights, kind="stable")
    return DenseScores(
        region=region,
        heights=np.asarray(heights, dtype=np.float64)[order],
        levels=[grids[i] for i in order],
        origins=np.asarray(origins, dtype=np.float64).reshape(-1, 2)[order],
        strides=np.asarray(strides, dtype=np.float64)[order],
        part_names=part_names,
        part_offsets=[offsets[i] for i in order],
    )
