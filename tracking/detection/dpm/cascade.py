"""Star-cascade scoring: the DPM score of a root computed part by part, pruned early.

Felzenszwalb, Girshick, McAllester, "Cascade Object Detection with Deformable Part Models",
CVPR 2010. The score of a root (:mod:`.scoring`) is a sum of ``1 + P`` terms, the root response
and ``P`` deformed part responses. The cascade adds them one at a time and drops a root as soon
as its partial sum falls below the stage's threshold; most roots of a frame are dropped after
the first term, so most part responses are never computed. The first ``1 + P`` stages use
cheap approximate filters (features and filters projected on ``k`` principal directions, ``k``
of 32 multiply-adds per cell); the next ``1 + P`` stages replace each approximate term by the
exact one, so every root that passes all stages has exactly the score of :func:`.scoring.
score_level` and its argmax placements (ties of equal scores aside).

Two pruning rules per part stage, both with thresholds fitted on positive examples
(``devtools/cascade_fit.py``): the partial score after the stage must reach ``stage[i]``, and a
placement ``q`` of the part is tried only when ``partial - d(q) >= deformation[i]`` (the
deformation cost alone already rules the others out). Thresholds that are ``-inf`` prune
nothing: the cascade is then exact. Fitted thresholds are the lowest partial scores of the
positives that scored above the detection threshold ("probably approximately admissible", §4
of the paper): a true detection below them is lost.

The compiled kernels of :mod:`.kernels` do the per-root work: the cascade's lazy search, and,
without a projection (regions of interest, dense scores), the exact scoring of every root of a
rectangle. :func:`cascade_level` scores one level with either.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from tracking.compiled import call_kernel
from tracking.detection.dpm.kernels import (
    KernelFilters,
    cascade_roots,
    exact_component,
    flat,
    kernel_filters,
    project_cells,
)
from tracking.detection.dpm.model import DpmComponent, DpmModel
from tracking.detection.dpm.pyramid import PyramidLevel
from tracking.detection.dpm.scoring import LevelRoots, LevelScores, root_grid, root_rectangle

__all__ = [
    "CascadeThresholds",
    "PcaProjection",
    "cascade_level",
    "cascade_level_roots",
    "cascade_path",
    "load_cascade",
    "pca_projection",
    "select_thresholds",
]

DEFAULT_PCA_DIMS = 6


@dataclass(frozen=True, slots=True)
class PcaProjection:
    """Principal directions of a model's filter cells and the filters projected on them.

    Attributes
    ----------
    basis:
        ``(32, k)`` float32 orthonormal columns: the top eigenvectors of ``sum_cells w w^T``
        over every cell of every filter, i.e. the ``k``-dimensional subspace that keeps the
        most of the filters' energy. A feature cell ``f`` becomes ``basis^T f`` and a filter
        cell ``w`` becomes ``basis^T w``; their dot product approximates ``w . f`` by
        ``w . P f`` with ``P`` the projector on the subspace.
    roots, parts:
        Per component: the projected ``(h, w, k)`` root filter and ``(P, h, w, k)`` parts.
    """

    basis: np.ndarray
    roots: tuple[np.ndarray, ...]
    parts: tuple[np.ndarray, ...]
    _directions: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # the basis's columns as contiguous rows, as project_cells reads them: made once, not
        # per pyramid level
        directions = np.ascontiguousarray(self.basis.T, dtype=np.float32)
        object.__setattr__(self, "_directions", directions)

    def project(self, features: np.ndarray) -> np.ndarray:
        """``(H, W, 32)`` features -> ``(H, W, k)`` float32: ``basis^T f`` per cell."""
        h, w, c = features.shape
        out = np.empty((h * w, self.basis.shape[1]), dtype=np.float32)
        cells = np.ascontiguousarray(features, dtype=np.float32).reshape(-1, c)
        project_cells(cells, self._directions, out)
        return out.reshape(h, w, -1)


def pca_projection(model: DpmModel, dims: int = DEFAULT_PCA_DIMS) -> PcaProjection:
    """The model's :class:`PcaProjection` on ``dims`` directions.

    The paper projects on the principal components of HOG features of training images; we use
    the model's own filter cells instead, which needs no data and keeps the part of the filters
    that the score depends on (the exact stages correct whatever the projection loses).
    """
    cells = np.concatenate(
        [s.weights.reshape(-1, model.num_features) for c in model.components for s in c.symbols]
    ).astype(np.float64)
    _, vectors = np.linalg.eigh(cells.T @ cells)
    basis = np.ascontiguousarray(vectors[:, ::-1][:, :dims], dtype=np.float32)
    roots = tuple(np.ascontiguousarray(c.root.weights @ basis) for c in model.components)
    parts = tuple(
        np.ascontiguousarray(np.stack([p.weights @ basis for p in c.parts]))
        if c.parts
        else np.zeros((0, 1, 1, dims), dtype=np.float32)
        for c in model.components
    )
    return PcaProjection(basis, roots, parts)


@dataclass(frozen=True, slots=True)
class CascadeThresholds:
    """Pruning thresholds of the ``2 (1 + P)`` stages, for one detection threshold.

    Attributes
    ----------
    score_threshold:
        The detection threshold the thresholds were fitted for: they are admissible for the
        positives scoring above it (use them with that threshold or a higher one).
    stage:
        ``(2 + 2 P,)``: lowest admissible partial score after stage ``i`` (stage 0 the
        approximate root, ``1..P`` the approximate parts, ``P + 1`` the exact root, then the
        exact parts).
    deformation:
        ``(2 + 2 P,)``: lowest admissible ``partial - deformation cost`` of a part placement
        (entries 0 and ``P + 1``, the root stages, are unused).
    """

    score_threshold: float
    stage: np.ndarray
    deformation: np.ndarray

    @classmethod
    def exact(cls, num_parts: int) -> CascadeThresholds:
        """No pruning: every root gets its exact score."""
        n = 2 + 2 * num_parts
        return cls(-math.inf, np.full(n, -np.inf), np.full(n, -np.inf))


def cascade_path(model_path: str | os.PathLike[str]) -> Path:
    """``<model>.cascade.json`` beside the model file."""
    path = Path(model_path)
    return path.with_name(path.stem + ".cascade.json")


def load_cascade(path: str | os.PathLike[str]) -> list[CascadeThresholds]:
    """The thresholds of a ``.cascade.json`` file, lowest detection threshold first."""
    try:
        payload = json.loads(Path(path).read_text())
        out = [
            CascadeThresholds(
                float(row["score_threshold"]),
                np.array(row["stage"], dtype=np.float64),
                np.array([-np.inf if v is None else v for v in row["deformation"]], np.float64),
            )
            for row in payload["thresholds"]
        ]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path} is not a cascade thresholds file: {error}") from error
    return sorted(out, key=lambda t: t.score_threshold)


def select_thresholds(
    table: list[CascadeThresholds], score_threshold: float
) -> CascadeThresholds | None:
    """The thresholds fitted for the highest detection threshold not above ``score_threshold``.

    Those were fitted on a superset of the positives scoring above ``score_threshold``, so
    they are admissible for them. ``None`` when every entry was fitted for a higher one.
    """
    usable = [t for t in table if t.score_threshold <= score_threshold]
    return max(usable, key=lambda t: t.score_threshold) if usable else None


def _approx_root_responses(
    features: np.ndarray, roots: tuple[np.ndarray, ...], grid: tuple[int, int]
) -> list[np.ndarray]:
    """Responses of the projected root filters on the ``grid`` of root positions.

    One OpenCV correlation per channel: with ``k = 6`` channels that is about 2.5x faster than
    the matrix-product route of :func:`.responses.filter_responses`, which suits 32 channels.
    Positions where a root does not fit get ``-inf``. The float32 sums differ from the
    product's in the last bits; the exact stage subtracts these very values again.
    """
    height, width, channels = features.shape
    planes = [np.ascontiguousarray(features[..., c]) for c in range(channels)]
    out = []
    for weights in roots:
        h, w = weights.shape[:2]
        total = np.zeros((height, width), dtype=np.float32)
        for c, plane in enumerate(planes):
            kernel = np.ascontiguousarray(weights[..., c])
            total += cv2.filter2D(plane, cv2.CV_32F, kernel, anchor=(0, 0),
                                  borderType=cv2.BORDER_CONSTANT)  # fmt: skip
        response = np.full(grid, -np.inf, dtype=np.float32)
        fit_h, fit_w = min(grid[0], height - h + 1), min(grid[1], width - w + 1)
        response[:fit_h, :fit_w] = total[:fit_h, :fit_w]
        out.append(response)
    return out


def _component_offset(component: DpmComponent, level: PyramidLevel) -> float:
    """The constant terms of a root's score on ``level``: rule offsets and octave weights."""
    total = component.bias + component.location[level.octave]
    for symbol in component.symbols:
        table_level = level.index - level.interval * symbol.anchor[2]
        octave = min(max(table_level, 0) // level.interval, 2)
        total += symbol.bias + symbol.location[octave]
    return float(total)


def cascade_level(
    model: DpmModel,
    features: dict[int, np.ndarray],
    projected: dict[int, np.ndarray] | None,
    projection: PcaProjection | None,
    level: PyramidLevel,
    pad: tuple[int, int],
    thresholds: CascadeThresholds,
    threshold: float,
    window: int = 4,
    positions: np.ndarray | None = None,
    rows: tuple[int, int] | None = None,
    cols: tuple[int, int] | None = None,
    filters: tuple[KernelFilters, ...] | None = None,
) -> tuple[LevelScores, list[tuple[np.ndarray, np.ndarray]]] | None:
    """Scores of the roots of ``level`` that pass the cascade, in :class:`LevelScores` form.

    Parameters
    ----------
    features, projected:
        Exact and projected (:meth:`PcaProjection.project`) padded maps by level index; must
        hold ``level.index`` and, for models with parts, ``level.index - level.interval``.
    projection:
        The model's projection; ``None`` (or ``projected`` None): no cascade, every root of
        the rectangle is scored exactly, densely (``thresholds`` are not read).
    thresholds:
        Stage thresholds (:meth:`CascadeThresholds.exact` for none).
    threshold:
        Detection threshold: roots at or below it get ``-inf``.
    window:
        Largest part displacement in cells (as :func:`.scoring.score_level`).
    positions:
        ``(N, 2)`` root (row, col) positions to consider; default every one.
    rows, cols:
        Half-open ranges of root positions (padded-map indices) to score; default all.
    filters:
        :func:`kernel_filters` of the model for ``pad`` and, when the cascade runs, for
        ``projection`` (made here if ``None``; callers scoring many levels make them once).

    Returns
    -------
    (LevelScores, records) or None
        Every root that passed with its exact score (``-inf`` elsewhere), and per component the
        ``(stages, margins)`` partial scores of those roots (filled when ``positions`` is given
        with a projection, for fitting; empty otherwise). ``None`` when the rectangle is empty.
    """
    setup = _level_setup(model, features, projected, projection, level, pad, rows, cols, filters)
    if setup is None:
        return None
    (r0, c0), (ny, nx), filters, approx_roots = setup
    components = model.components
    n_symbols = max(len(c.symbols) for c in components)
    component_scores = np.full((len(components), ny, nx), -np.inf)
    placements = np.full((len(components), n_symbols, ny, nx, 2), -1, dtype=np.int32)
    records = []
    for ci, component in enumerate(components):
        n_parts = len(component.parts)
        # approx_roots come with the projection and projected features only
        if approx_roots is not None and projected is not None and projection is not None:
            found, found_cols, scores, place, stages, margins = _cascade_component(
                model, features, projected, projection, level, thresholds, threshold,
                window, positions, (r0, c0), ci, filters[ci], approx_roots[ci],
            )  # fmt: skip
            component_scores[ci, found, found_cols] = scores
            for p in range(n_parts):
                placements[ci, 1 + p, found, found_cols] = place[:, p]
            records.append((stages, margins))
        else:
            scores, place = _exact_component(
                model, features, level, threshold, window, positions, (r0, c0), (ny, nx), ci,
                filters[ci],
            )  # fmt: skip
            component_scores[ci] = scores
            found, found_cols = np.nonzero(scores > -np.inf)
            placements[ci, 1 : 1 + n_parts] = place
            records.append((np.zeros((0, 2 + 2 * n_parts)), np.zeros((0, 2 + 2 * n_parts))))
        placements[ci, 0, found, found_cols] = _root_placements(
            component, (r0, c0), found, found_cols
        )
    return LevelScores.of_mixture(level, (r0, c0), component_scores, placements), records


def cascade_level_roots(
    model: DpmModel,
    features: dict[int, np.ndarray],
    projected: dict[int, np.ndarray] | None,
    projection: PcaProjection | None,
    level: PyramidLevel,
    pad: tuple[int, int],
    thresholds: CascadeThresholds,
    threshold: float,
    window: int = 4,
    rows: tuple[int, int] | None = None,
    cols: tuple[int, int] | None = None,
    filters: tuple[KernelFilters, ...] | None = None,
) -> LevelRoots | None:
    """The roots of ``level`` above ``threshold`` that :func:`cascade_level` scores, alone.

    Arguments as :func:`cascade_level`'s. With the cascade, the roots it finds are kept as they
    come out of the kernel, with no grid of every position and placement of the level (most
    of a frame's scoring time outside the kernels went into filling and reducing those);
    without it, the exact scores are scored densely and their roots above ``threshold`` kept.
    Either way the same roots, scores and placements as ``cascade_level(...)[0].roots(
    threshold)``.
    """
    if projection is None or projected is None:
        result = cascade_level(
            model, features, projected, projection, level, pad, thresholds, threshold,
            window, rows=rows, cols=cols, filters=filters,
        )  # fmt: skip
        return None if result is None else result[0].roots(threshold)
    setup = _level_setup(model, features, projected, projection, level, pad, rows, cols, filters)
    if setup is None:
        return None
    origin, _, filters, approx_roots = setup
    assert approx_roots is not None, "made with the projection and projected features"
    n_symbols = max(len(c.symbols) for c in model.components)
    found_rows, found_cols, found_scores, found_components, found_places = [], [], [], [], []
    for ci, component in enumerate(model.components):
        found, columns, scores, place, _, _ = _cascade_component(
            model, features, projected, projection, level, thresholds, threshold, window,
            None, origin, ci, filters[ci], approx_roots[ci],
        )  # fmt: skip
        placements = np.full((found.size, n_symbols, 2), -1, dtype=np.int64)
        placements[:, 0] = _root_placements(component, origin, found, columns)
        placements[:, 1 : 1 + len(component.parts)] = place
        found_rows.append(found)
        found_cols.append(columns)
        found_scores.append(scores)
        found_components.append(np.full(found.size, ci))
        found_places.append(placements)
    return LevelRoots.of_mixture(
        level, origin, *(np.concatenate(a) for a in (
            found_rows, found_cols, found_scores, found_components, found_places
        )),
    )  # fmt: skip


def _level_setup(
    model: DpmModel,
    features: dict[int, np.ndarray],
    projected: dict[int, np.ndarray] | None,
    projection: PcaProjection | None,
    level: PyramidLevel,
    pad: tuple[int, int],
    rows: tuple[int, int] | None,
    cols: tuple[int, int] | None,
    filters: tuple[KernelFilters, ...] | None,
) -> tuple[tuple[int, int], tuple[int, int], tuple[KernelFilters, ...], list | None] | None:
    """What scoring a level's rectangle needs: its origin and shape, the kernel filters and,
    with the cascade, each component's approximate root responses on it; ``None`` when the
    rectangle is empty."""
    root_features = features[level.index]
    rectangle = root_rectangle(model, root_features.shape, rows, cols)
    if rectangle is None:
        return None
    (r0, r1), (c0, c1) = rectangle
    if filters is None:
        filters = kernel_filters(model, pad, projection if projected is not None else None)
    elif projection is not None and projected is not None:
        # the compiled cascade reads the projected parts without bounds checks
        for kernel in filters:
            n_parts, part_rows, width = kernel.parts.shape
            expected = (
                n_parts, part_rows, width // root_features.shape[2] * projection.basis.shape[1]
            )  # fmt: skip
            if n_parts and kernel.approx_parts.shape != expected:
                raise ValueError(
                    "filters without the projected parts: make them with "
                    "kernel_filters(model, pad, projection) for the cascade"
                )
    approx_roots = None
    if projection is not None and projected is not None:
        full = _approx_root_responses(
            projected[level.index], projection.roots, root_grid(model, root_features.shape)
        )
        approx_roots = [r[r0:r1, c0:c1] for r in full]
    return (r0, c0), (r1 - r0, c1 - c0), filters, approx_roots


def _root_placements(
    component: DpmComponent, origin: tuple[int, int], rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """``(N, 2)`` padded-map ``(col, row)`` of the root filter of the roots at grid elements
    ``(rows, cols)`` of a rectangle starting at ``origin``."""
    return np.column_stack(
        [cols + origin[1] + component.root.anchor[0], rows + origin[0] + component.root.anchor[1]]
    )


def _chosen(start: np.ndarray, positions: np.ndarray | None, origin: tuple[int, int]) -> np.ndarray:
    """``start`` kept at the root ``positions`` (padded-map indices) only, ``-inf`` elsewhere."""
    if positions is None:
        return start
    chosen = np.full_like(start, -np.inf)
    at = positions[:, 0] - origin[0], positions[:, 1] - origin[1]
    chosen[at] = start[at]
    return chosen


def _cascade_component(
    model: DpmModel,
    features: dict[int, np.ndarray],
    projected: dict[int, np.ndarray],
    projection: PcaProjection,
    level: PyramidLevel,
    thresholds: CascadeThresholds,
    threshold: float,
    window: int,
    positions: np.ndarray | None,
    origin: tuple[int, int],
    ci: int,
    kernel: KernelFilters,
    approx_root: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """One component's roots through the compiled cascade: ``(rows, cols, scores,
    placements (N, P, 2) (col, row), stages, margins)`` as :func:`.kernels.cascade_roots`."""
    component = model.components[ci]
    root_features = features[level.index]
    origin_array = np.array(origin, dtype=np.int64)
    start = _chosen(
        approx_root + np.float32(_component_offset(component, level)), positions, origin
    )
    part_level = level.index - level.interval * kernel.part_levels
    part_grid = features[part_level].shape[:2]  # cells (the flat maps hold W C columns)
    n_parts = len(component.parts)
    n_stages = 2 + 2 * n_parts
    return call_kernel(
        cascade_roots, start, approx_root, flat(root_features), kernel.root,
        kernel.root_anchor + origin_array, flat(projected[part_level]),
        flat(features[part_level]), kernel.approx_parts, kernel.parts,
        projection.basis.shape[1], root_features.shape[2],
        kernel.part_anchors + kernel.steps[:, None] * origin_array, kernel.steps,
        kernel.deformations, window,
        np.asarray(thresholds.stage[:n_stages], dtype=np.float64),
        np.asarray(thresholds.deformation[:n_stages], dtype=np.float64),
        float(threshold),
        # np.zeros maps zero pages that memory touches only where a response is computed
        np.empty((2, n_parts, *part_grid), dtype=np.float32),
        np.zeros((2, n_parts, *part_grid), dtype=np.bool_),
        positions is not None,
    )  # fmt: skip


def _exact_component(
    model: DpmModel,
    features: dict[int, np.ndarray],
    level: PyramidLevel,
    threshold: float,
    window: int,
    positions: np.ndarray | None,
    origin: tuple[int, int],
    shape: tuple[int, int],
    ci: int,
    kernel: KernelFilters,
) -> tuple[np.ndarray, np.ndarray]:
    """One component's exact dense scores and placements on the rectangle
    (:func:`.kernels.exact_component`)."""
    component = model.components[ci]
    root_features = features[level.index]
    origin_array = np.array(origin, dtype=np.int64)
    # the root's constant terms where it fits, -inf elsewhere
    start = np.full(shape, -np.inf, dtype=np.float32)
    h, w = component.root.size
    start[: max(root_features.shape[0] - h + 1 - origin[0], 0),
          : max(root_features.shape[1] - w + 1 - origin[1], 0)] = np.float32(
        _component_offset(component, level)
    )  # fmt: skip
    start = _chosen(start, positions, origin)
    part_level = level.index - level.interval * kernel.part_levels
    return call_kernel(
        exact_component, start, flat(root_features), kernel.root,
        kernel.root_anchor + origin_array, flat(features[part_level]), kernel.parts,
        root_features.shape[2], kernel.part_anchors + kernel.steps[:, None] * origin_array,
        kernel.steps, kernel.deformations, window, float(threshold),
    )  # fmt: skip
