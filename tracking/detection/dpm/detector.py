"""The DPM person detector: voc-release5 detection with a mixture of star models.

``detect`` follows voc-release5 ``imgdetect.m`` / ``pascal_test.m`` / ``bboxpred_rescore.m``:
the feature pyramid (:mod:`.pyramid`), star-model scores on every root level (:mod:`.scoring`),
every root position scoring above the threshold as a candidate with its filter boxes, then
clipping, suppression, bounding-box regression, clipping and suppression (:mod:`.boxes`).

``detect_region`` and ``dense_scores`` score only root windows centred inside a region of
interest, only at the pyramid levels whose window heights fall in a given range, each level on a
crop of the frame holding just those windows and the reach of their parts: the cost scales with
the region and the height range, not with the frame. A crop's cell grid starts at the crop's
corner, so region scores sample positions up to a cell apart from the full frame's and may
differ from them by what a shift of a fraction of a cell changes (both are exact DPM scores of
their windows).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from tracking.detection.base import DenseScores, Detections
from tracking.detection.calibration import (
    LogisticCalibration,
    calibration_path,
    load_calibration,
)
from tracking.detection.dpm.boxes import Candidates, candidates, postprocess
from tracking.detection.dpm.cascade import (
    CascadeThresholds,
    PcaProjection,
    cascade_level,
    cascade_level_roots,
    cascade_path,
    load_cascade,
    pca_projection,
    select_thresholds,
)
from tracking.detection.dpm.config import DpmConfig
from tracking.detection.dpm.dense import dense_scores
from tracking.detection.dpm.kernels import KernelFilters, kernel_filters, kernels_apply
from tracking.detection.dpm.model import DpmModel, load_dpm_model
from tracking.detection.dpm.parts import model_part_names
from tracking.detection.dpm.pyramid import (
    PyramidLevel,
    level_chains,
    level_features,
    pyramid_levels,
)
from tracking.detection.dpm.scoring import LevelRoots, LevelScores, root_grid, score_level
from tracking.detection.regions import checked_heights, checked_region, clip_region
from tracking.types import Box, check_pixel_values, validate_frame

__all__ = [
    "DEFAULT_DPM_CALIBRATION",
    "KNOWN_CALIBRATIONS",
    "KNOWN_CASCADES",
    "DpmConfig",
    "DpmDetector",
]

# Fitted with our calibration command on 1 frame in 4 of PETS09-S2L1 and TUD-Stadtmitte
# (244 frames; 1324 positives, 1759 negatives), default options (suppression by IoU 0.5 since
# 2026-12-05; release 5's gave a = 3.73723, b = -0.320898), threshold model.thresh - 1:
#   python -m devtools.calibrate --detector dpm --model INRIA/inriaperson_final.mat \
#       --sequences <data>/mot/PETS09-S2L1 <data>/mot/TUD-Stadtmitte --step 4
# p = 0.5 at a score of 0.105 (the model's threshold, -0.126, gives p = 0.31).
DEFAULT_DPM_CALIBRATION = LogisticCalibration(
    a=3.41073,
    b=-0.357880,
    source="DPM inriaperson_final.mat, threshold -1.126; fitted on PETS09-S2L1 and "
    "TUD-Stadtmitte (1 frame in 4)",
)
"""Used for a model without a calibration file beside it, none configured and no entry in
:data:`KNOWN_CALIBRATIONS`; fitted for the INRIA person model (other models' scores are on a
similar scale but not the same: fit theirs with ``python -m devtools.calibrate``)."""

KNOWN_CALIBRATIONS: Mapping[tuple[str, int], LogisticCalibration] = MappingProxyType(
    {
        ("inriaperson", 2): DEFAULT_DPM_CALIBRATION,
        # VOC2007/person_final.mat, fitted the same way (1283 positives, 81358 negatives,
        # threshold -2.442; release 5's suppression left 8095 negatives and gave a = 4.83467,
        # b = 1.43075); p = 0.5 at a score of -0.188.
        ("person", 6): LogisticCalibration(
            a=4.90847,
            b=0.920655,
            source="DPM VOC2007 person_final.mat, threshold -2.442; fitted on PETS09-S2L1 and "
            "TUD-Stadtmitte (1 frame in 4)",
        ),
    }
)
"""Default calibrations of the voc-release5 person models, by ``(model.name, components)``."""

KNOWN_CASCADES: Mapping[tuple[str, int], Path] = MappingProxyType(
    {
        # Fitted with our command on 180 positives of the OTB sequences Crossing, Skating1 and
        # Basketball (1 frame in 4), none of them a benchmark sequence:
        #   python -m devtools.cascade_fit --model INRIA/inriaperson_final.mat \
        #       --sequences <data>/otb/Crossing <data>/otb/Skating1 \
        #       <data>/otb/Basketball_first200 --out tracking/detection/dpm/cascades/...
        ("inriaperson", 2): Path(__file__).with_name("cascades") / "inriaperson.cascade.json",
    }
)
"""Cascade thresholds shipped for the voc-release5 person models, by ``(name, components)``."""

_HOG_BORDER = 1.5  # root cells a crop needs beyond the parts' reach for exact-enough HOG


@dataclass(frozen=True, slots=True)
class _Plan:
    """One root level to score: its levels, the image they come from, the positions."""

    root: PyramidLevel
    levels: tuple[PyramidLevel, ...]  # root level and, for models with parts, its part level
    corner: tuple[int, int]  # (x, y) of the image in the frame
    image: np.ndarray
    rows: tuple[int, int] | None = None  # root positions (padded-map indices); None: all
    cols: tuple[int, int] | None = None


_CASCADE_MIN_ROOTS = 225
"""Root positions from which a region's level is scored with the cascade. Below, about a region
the size of the person (15 x 15 positions of a window 15 cells tall), projecting the level's
features for the cascade costs more than the exact kernel does: 6.9 against 4.4 ms per region
of a person's half height, 13.4 against 19.5 ms at twice the height (PETS09-S2L1)."""


def _positions(plan: _Plan) -> float:
    """The number of root positions of ``plan`` (infinite: all of its level's)."""
    if plan.rows is None or plan.cols is None:
        return math.inf
    return (plan.rows[1] - plan.rows[0]) * (plan.cols[1] - plan.cols[0])


@dataclass(slots=True)
class DpmDetector:
    """Person detector running a voc-release5 mixture of star models.

    Parameters
    ----------
    model:
        A loaded model (:func:`~tracking.detection.dpm.model.load_dpm_model`).
    config:
        Options; the defaults reproduce voc-release5.
    calibration:
        Score-to-probability mapping; ``None``: ``config.calibration``, else the
        ``<model>.calibration.json`` beside the model file, else the model's entry in
        :data:`KNOWN_CALIBRATIONS`, else :data:`DEFAULT_DPM_CALIBRATION`.

    Attributes
    ----------
    part_names:
        Named part slots of :attr:`Detections.parts` (:mod:`.parts`).
    """

    model: DpmModel
    config: DpmConfig = field(default_factory=DpmConfig)
    calibration: LogisticCalibration | None = None
    part_names: tuple[str, ...] = field(init=False)
    _slots: tuple[tuple[int, ...], ...] = field(init=False, repr=False)
    _cascade: tuple[CascadeThresholds, PcaProjection] | None = field(init=False, repr=False)
    _exact: CascadeThresholds = field(init=False, repr=False)
    _filters: tuple[KernelFilters, ...] | None = field(init=False, repr=False)
    _pool: ThreadPoolExecutor | None = field(init=False, repr=False, compare=False)
    _workers: int = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.part_names, self._slots = model_part_names(self.model)
        if self.calibration is None:
            self.calibration = _find_calibration(self.model, self.config)
        self._exact = CascadeThresholds.exact(self.model.num_parts)
        # models the compiled kernels cannot score go through the general numpy scoring
        kernels = kernels_apply(self.model)
        # one pool for the detector's life (its threads start on first use and end with it):
        # starting threads per call cost a region of interest about a tenth of its time
        self._workers = self.config.workers or cv2.getNumThreads()
        self._pool = ThreadPoolExecutor(self._workers, "dpm-level") if self._workers > 1 else None
        self._cascade = None
        projection = None
        if self.config.cascade and self.config.deformation_window is not None and kernels:
            thresholds = _find_cascade(self.model, self.config, self.threshold)
            if thresholds is not None:
                projection = pca_projection(self.model)
                self._cascade = thresholds, projection
        # one set of filters for both kernels (the exact one ignores the projected parts)
        self._filters = kernel_filters(self.model, self.pad, projection) if kernels else None

    @classmethod
    def from_file(
        cls, path: str | os.PathLike[str], config: DpmConfig | None = None
    ) -> DpmDetector:
        """Load a voc-release5 model file (raises ``ModelFileError``) and wrap it."""
        return cls(load_dpm_model(path), config or DpmConfig())

    @property
    def threshold(self) -> float:
        """The score threshold in use."""
        t = self.config.threshold
        return self.model.threshold if t is None else float(t)

    @property
    def cascade(self) -> CascadeThresholds | None:
        """The star-cascade thresholds ``detect`` and ``detect_region`` prune with; ``None``:
        they score exactly."""
        return None if self._cascade is None else self._cascade[0]

    @property
    def interval(self) -> int:
        """Pyramid levels per octave in use (``config.levels_per_octave`` or the model's)."""
        return self.config.levels_per_octave or self.model.interval

    @property
    def pad(self) -> tuple[int, int]:
        """Feature-map padding ``(pad_y, pad_x)`` in cells (``getpadding.m``: the max size)."""
        return self.model.max_size

    # ------------------------------------------------------------------ levels and scoring
    def search_levels(
        self,
        shape: tuple[int, ...],
        heights: tuple[float | None, float | None] = (None, None),
        nearest: bool = False,
    ) -> list[tuple[PyramidLevel, tuple[PyramidLevel, ...]]]:
        """The levels that can hold a root (``gdetect_parse.m``) in an image of ``shape``.

        Only levels where some component's window is ``heights[0] .. heights[1]`` pixels tall
        (``None``: unbounded), each with the levels its score reads: itself and, for a model
        with parts, the level one octave finer where the parts sit. With ``nearest``, heights
        that fall between two levels (a coarse pyramid of a few levels per octave and a narrow
        range) give the level whose windows come nearest to them instead of no level: a region
        around a person is then searched at the closest scale the pyramid has. Heights beyond
        either end of the pyramid still give no level.
        """
        model = self.model
        levels = pyramid_levels(
            shape, model.sbin, self.interval, model.extra_octave, self.config.upscale_for(shape)
        )
        low = heights[0] if heights[0] is not None else 0.0
        high = heights[1] if heights[1] is not None else math.inf
        window_heights = [c.window[0] for c in model.components]
        roots = [level for level in levels if level.index >= self.interval]

        def outside(level: PyramidLevel) -> float:
            """How many times too small or too large the level's nearest window is; 1 inside."""
            return min(
                max(low / (h * level.cell), h * level.cell / high, 1.0) for h in window_heights
            )

        chosen = [level for level in roots if outside(level) == 1.0]
        if not chosen and nearest:
            # between two levels, not beyond either end of the pyramid: people smaller than
            # its smallest window or larger than the frame are not searched at another size
            smaller = any(max(window_heights) * level.cell < low for level in roots)
            larger = any(min(window_heights) * level.cell > high for level in roots)
            if smaller and larger:
                chosen = [min(roots, key=outside)]
        parts = any(c.parts for c in model.components)
        return [
            (level, (level, levels[level.index - self.interval]) if parts else (level,))
            for level in chosen
        ]

    def _run(
        self, plans: list[_Plan], shared: np.ndarray | None = None, cascade: bool = False
    ) -> list[tuple]:
        """Score the plans; ``shared``: one image for all plans, features computed once.

        ``cascade``: for detection, each plan's roots above the threshold (:class:`LevelRoots`),
        with the star cascade when the detector has one, except a region's level with fewer
        than ``_CASCADE_MIN_ROOTS`` root positions; otherwise every root's exact score
        (:class:`LevelScores`: dense scores need them all).
        With ``shared``, one job per halving chain of root levels (:func:`level_chains`)
        computes the chain's features and scores its levels: a root level's part level is in
        the same chain (one octave finer: the same image, or the one it was halved from), so
        the jobs are independent and no thread waits for the others' features. A pyramid of
        few chains is scored level by level instead (:meth:`_score_by_level`).
        """
        cascade_setup = self._cascade if cascade else None
        projection = cascade_setup[1] if cascade_setup is not None else None

        def score(
            plan: _Plan,
            features: dict[int, np.ndarray],
            projected: dict[int, np.ndarray],
            pruned: bool,
        ) -> LevelScores | LevelRoots | None:
            if self.config.deformation_window is None or self._filters is None:
                scores = score_level(
                    self.model, features, plan.root, self.pad, plan.rows, plan.cols,
                    self.config.deformation_window,
                )  # fmt: skip
                if scores is None or not cascade:
                    return scores
                return scores.roots(self.threshold)
            if cascade:  # the roots above the threshold, pruned or scored exactly
                return cascade_level_roots(
                    self.model, features, projected if pruned else None,
                    projection if pruned else None, plan.root, self.pad,
                    cascade_setup[0] if pruned and cascade_setup is not None else self._exact,
                    self.threshold,
                    self.config.deformation_window, rows=plan.rows, cols=plan.cols,
                    filters=self._filters,
                )  # fmt: skip
            # every root exactly, densely in the compiled kernel
            result = cascade_level(
                self.model, features, None, None, plan.root, self.pad, self._exact, -math.inf,
                self.config.deformation_window, rows=plan.rows, cols=plan.cols,
                filters=self._filters,
            )  # fmt: skip
            return None if result is None else result[0]

        def features_of(
            group: list[_Plan], image: np.ndarray
        ) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], bool]:
            levels = {level.index: level for plan in group for level in plan.levels}
            features = level_features(image, list(levels.values()), self.pad)
            pruned = projection is not None and (
                shared is not None or sum(_positions(plan) for plan in group) >= _CASCADE_MIN_ROOTS
            )
            # the cascade's approximate stages read the features projected
            projected = (
                {k: projection.project(v) for k, v in features.items()}
                if pruned and projection is not None
                else {}
            )
            return features, projected, pruned

        def score_all(
            group: list[_Plan], image: np.ndarray
        ) -> list[LevelScores | LevelRoots | None]:
            prepared = features_of(group, image)
            return [score(plan, *prepared) for plan in group]

        if shared is None:
            groups = [[plan] for plan in plans]
        else:
            chain_of = {
                level.index: i
                for i, chain in enumerate(level_chains([plan.root for plan in plans]))
                for level in chain
            }
            by_chain: dict[int, list[_Plan]] = {}
            for plan in plans:
                by_chain.setdefault(chain_of[plan.root.index], []).append(plan)
            groups = [by_chain[i] for i in sorted(by_chain)]  # largest images first
        if shared is not None and self._pool is not None and len(groups) < 3 * self._workers:
            results = self._score_by_level(self._pool, groups, features_of, score, shared)
        else:
            jobs = [
                (lambda g=group: score_all(g, shared if shared is not None else g[0].image))
                for group in groups
            ]
            results = [s for group_scores in self._map(jobs) for s in group_scores]
        ordered = [plan for group in groups for plan in group]
        return [(s, plan.corner) for s, plan in zip(results, ordered, strict=True) if s is not None]

    def _score_by_level(
        self,
        pool: ThreadPoolExecutor,
        groups: list[list[_Plan]],
        features_of: Callable[[list[_Plan], np.ndarray], tuple],
        score: Callable[..., LevelScores | LevelRoots | None],
        image: np.ndarray,
    ) -> list[LevelScores | LevelRoots | None]:
        """Score a frame's few halving chains (fewer than 3 per thread: a pyramid of up to 5
        levels per octave on two threads) with its levels as the jobs: the chains' features
        first, one job each, then each root level as soon as its chain's features are made,
        largest first. Results follow ``groups``' order.

        One job per chain leaves a thread idle when the chains are few and unequal: with 2
        levels per octave the first chain holds twice the pixels of the second (jobs of 47
        and 31 ms on a TUD-Stadtmitte frame), and by level the frame took 37 ms instead of 50;
        with 5 levels 80 instead of 88. With 10 the chains balance by themselves, and making
        all their features before scoring would hold them all in memory at once.
        """

        def prepare(group: list[_Plan]) -> list[Future]:
            prepared = features_of(group, image)
            # submitted from the pool's own thread behind the chains' feature jobs, which are
            # all queued first: no job ever waits for another, so no thread blocks
            largest_first = sorted(range(len(group)), key=lambda i: group[i].root.cell)
            futures = {i: pool.submit(score, group[i], *prepared) for i in largest_first}
            return [futures[i] for i in range(len(group))]

        chains = [pool.submit(prepare, group) for group in groups]
        return [level.result() for chain in chains for level in chain.result()]

    def _map(self, jobs: Sequence[Callable[[], object]]) -> list:
        """Run ``jobs`` in order, on ``config.workers`` threads when there are several."""
        if self._pool is not None and len(jobs) > 1:
            return list(self._pool.map(lambda job: job(), jobs))
        return [job() for job in jobs]

    def _detections(self, c: Candidates, shape: tuple[int, ...]) -> Detections:
        config = self.config
        c = postprocess(
            self.model, c, shape, config.nms_overlap, config.bbox_prediction, config.nms_criterion
        )
        parts = np.full((c.scores.size, len(self.part_names), 4), np.nan)
        for ci, slots in enumerate(self._slots):
            sel = np.flatnonzero(c.components == ci)
            if sel.size:
                parts[sel[:, None], np.array(slots)[None, :]] = c.filters[sel, 1 : 1 + len(slots)]
        calibration = self.calibration or DEFAULT_DPM_CALIBRATION
        return Detections(
            boxes=c.windows,
            scores=c.scores,
            probabilities=calibration.probability(c.scores),
            parts=parts,
            part_names=self.part_names,
        )

    # ------------------------------------------------------------------ regions of interest
    def _region_plans(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None
    ) -> tuple[Box, list[_Plan]] | None:
        """Per root level: the crop of the frame it needs and its root positions."""
        clipped = clip_region(region, frame.shape)
        if clipped is None:
            return None
        if heights is None:
            low, high = self.config.region_heights
            heights = (low * clipped.h, high * clipped.h)
        heights = checked_heights(heights)
        frame_h, frame_w = frame.shape[:2]
        pad_y, pad_x = self.pad
        window = self.config.deformation_window
        # parts move up to `window` part cells (half as many root cells) beyond the window
        reach = (4 if window is None else window) / 2 + _HOG_BORDER
        comps = self.model.components
        crops = []  # per root level: the level, the levels it reads, its crop, root positions
        for root, needed in self.search_levels(frame.shape, heights, nearest=True):
            c = root.cell
            margin_x = max(c_.window[1] / 2 + abs(c_.shift[1]) + reach for c_ in comps) * c
            margin_y = max(c_.window[0] / 2 + abs(c_.shift[0]) + reach for c_ in comps) * c
            x0 = max(0, math.floor(clipped.x - margin_x))
            y0 = max(0, math.floor(clipped.y - margin_y))
            x1 = min(frame_w, math.ceil(clipped.x + clipped.w + margin_x))
            y1 = min(frame_h, math.ceil(clipped.y + clipped.h + margin_y))
            if x1 - x0 < 2 or y1 - y0 < 2:
                continue
            # root positions (padded-map indices) whose window centre can lie in the region
            lo_x = min((clipped.x - x0) / c - k.window[1] / 2 + k.shift[1] for k in comps)
            hi_x = max(
                (clipped.x + clipped.w - x0) / c - k.window[1] / 2 + k.shift[1] for k in comps
            )
            lo_y = min((clipped.y - y0) / c - k.window[0] / 2 + k.shift[0] for k in comps)
            hi_y = max(
                (clipped.y + clipped.h - y0) / c - k.window[0] / 2 + k.shift[0] for k in comps
            )
            cells_y = max(math.floor((y1 - y0) * root.factor / root.hog_cell + 0.5) - 2, 0)
            cells_x = max(math.floor((x1 - x0) * root.factor / root.hog_cell + 0.5) - 2, 0)
            grid = root_grid(self.model, (cells_y + 2 * pad_y + 2, cells_x + 2 * pad_x + 2))
            rows = (max(math.ceil(lo_y + pad_y), 0), min(math.floor(hi_y + pad_y) + 1, grid[0]))
            cols = (max(math.ceil(lo_x + pad_x), 0), min(math.floor(hi_x + pad_x) + 1, grid[1]))
            if rows[1] <= rows[0] or cols[1] <= cols[0]:
                continue
            crops.append((root, needed, (x0, y0, x1, y1), rows, cols))
        if not crops:
            return clipped, []
        # one float copy of the union of the crops (the pyramid works in float32), each level
        # a view of it, instead of a copy per level
        ux0, uy0 = min(c[2][0] for c in crops), min(c[2][1] for c in crops)
        ux1, uy1 = max(c[2][2] for c in crops), max(c[2][3] for c in crops)
        union = frame[uy0:uy1, ux0:ux1].astype(np.float32)
        plans = [
            _Plan(
                root, needed, (x0, y0), union[y0 - uy0 : y1 - uy0, x0 - ux0 : x1 - ux0], rows, cols
            )
            for root, needed, (x0, y0, x1, y1), rows, cols in crops
        ]
        return clipped, plans

    # ------------------------------------------------------------------ public interface
    def detect(self, frame: np.ndarray) -> Detections:
        """People in the whole frame (RGB ``(H, W, 3)`` or grayscale, values 0..255)."""
        frame = _checked(frame)
        heights = (self.config.min_height, self.config.max_height)
        # the pyramid works in float32: one copy of the frame for every chain's job (each job
        # would otherwise convert the whole frame again)
        image = frame.astype(np.float32, copy=False)
        plans = [
            _Plan(r, needed, (0, 0), image)
            for r, needed in self.search_levels(frame.shape, heights)
        ]
        scored = self._run(plans, shared=image, cascade=True)
        found = candidates(
            self.model, scored, self.pad, self.threshold, limit=self.config.max_candidates
        )
        return self._detections(found, frame.shape)

    def detect_region(
        self,
        frame: np.ndarray,
        region: Box,
        heights: tuple[float, float] | None = None,
    ) -> Detections:
        """People whose window centre lies in ``region``, at window heights ``heights``.

        Parameters
        ----------
        frame:
            The whole frame.
        region:
            Region of interest; clipped to the frame. A region outside the frame gives no
            detections.
        heights:
            ``(min, max)`` detection-window heights in pixels; default
            ``config.region_heights`` times the region's height.
        """
        frame = _checked(frame)
        setup = self._region_plans(frame, checked_region(region), heights)
        if setup is None or not setup[1]:
            return Detections.empty(self.part_names)
        clipped, plans = setup
        found = candidates(
            self.model,
            self._run(plans, cascade=True),
            self.pad,
            self.threshold,
            region=clipped,
            limit=self.config.max_candidates,
        )
        return self._detections(found, frame.shape)

    def dense_scores(
        self,
        frame: np.ndarray,
        region: Box,
        heights: tuple[float, float] | None = None,
    ) -> DenseScores | None:
        """Raw scores of every root position and level whose window centre lies in ``region``.

        See :mod:`.dense` for the layout. Returns ``None`` when the region lies outside the
        frame or no level's window height is in ``heights`` (default: ``config.region_heights``
        times the region's height).
        """
        frame = _checked(frame)
        setup = self._region_plans(frame, checked_region(region), heights)
        if setup is None or not setup[1]:
            return None
        clipped, plans = setup
        return dense_scores(
            self.model, self._run(plans), self.pad, clipped, self.part_names, self._slots
        )


def _checked(frame: object) -> np.ndarray:
    frame = validate_frame(frame)
    check_pixel_values(frame, "frame")  # the pyramid's HOG features take the values unchecked
    return frame


def _find_calibration(model: DpmModel, config: DpmConfig) -> LogisticCalibration:
    if config.calibration is not None:
        return load_calibration(config.calibration)
    if model.path is not None:
        candidate = calibration_path(model.path)
        if candidate.is_file():
            return load_calibration(candidate)
    return KNOWN_CALIBRATIONS.get((model.name, len(model.components)), DEFAULT_DPM_CALIBRATION)


def _find_cascade(model: DpmModel, config: DpmConfig, threshold: float) -> CascadeThresholds | None:
    """The cascade thresholds for ``threshold`` (see ``DpmConfig.cascade_thresholds``)."""
    path = config.cascade_thresholds
    if path is None and model.path is not None and cascade_path(model.path).is_file():
        path = cascade_path(model.path)
    if path is None:
        path = KNOWN_CASCADES.get((model.name, len(model.components)))
    if path is None:
        return None
    table = load_cascade(path)
    stages = 2 + 2 * model.num_parts
    for row in table:
        if row.stage.shape != (stages,) or row.deformation.shape != (stages,):
            raise ValueError(
                f"{path} holds cascade thresholds of {row.stage.size} stages; model "
                f"{model.name!r} with {model.num_parts} parts needs {stages} "
                "(a file of another model?)"
            )
    return select_thresholds(table, threshold)
