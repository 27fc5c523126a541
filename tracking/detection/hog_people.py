"""The embedded default person detector: OpenCV's HOG + linear SVM people detector.

Dalal & Triggs, "Histograms of Oriented Gradients for Human Detection", CVPR 2005: a 64x128
window of 8x8-pixel cells, 16x16 blocks with stride 8 (3780 features), scored by the linear SVM
OpenCV ships (``cv2.HOGDescriptor_getDefaultPeopleDetector()``, trained on INRIA Person):
``score = w . x + b``. It needs no file beyond ``opencv-python-headless`` 4.x, so the service
runs out of the box; it has no parts (``part_names == ()``).

Detection: the frame is enlarged by ``upscale`` (people under ~100 px are below the window's
size; the issue's reference runs at 1.5x; by default the factor follows the frame's height, see
:meth:`HogPeopleConfig.upscale_for`), the window slides over the scale pyramid of OpenCV's
``detectMultiScale`` (the same levels, resizing and window positions), every window scoring above
``hit_threshold`` is kept with its raw score, and our voc-release5 suppression
(:func:`tracking.detection.nms.nms`) keeps the best of overlapping windows. The pyramid loop is
ours rather than ``detectMultiScale``'s because OpenCV 4.x's level threads append windows and
scores to its result under two separate locks: under CPU load a score can land beside another
level's window, so the same frame gave different detections from run to run (and a whole
video different tracks).

Windows are padded: the INRIA training windows put a 96-pixel person in 128 pixels with 16
pixels above and below (Dalal & Triggs, §3). Each box is shrunk about its centre to
``box_scale = (0.48, 0.73)`` of the window (width, height): the medians of
``ground-truth size / window size`` over 198 windows matched to people in PETS09-S2L1 and
TUD-Stadtmitte (interquartile ranges 0.43-0.54 and 0.70-0.76; centres agree within 2%).

Dense scores: the SVM slid over OpenCV's HOG descriptors of every window position
(``HOGDescriptor.compute`` on a crop, stride ``win_stride``) at each scale whose person height
fits the requested range -- exactly the scores ``detect`` thresholds.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import cv2
import numpy as np

from tracking.detection.base import DenseScores, Detections
from tracking.detection.calibration import LogisticCalibration
from tracking.detection.nms import NmsCriterion, check_nms_options, nms
from tracking.detection.regions import (
    centres_inside,
    checked_heights,
    checked_region,
    clip_boxes,
    clip_region,
)
from tracking.types import Box, is_int, validate_uint8_frame

__all__ = ["HOG_PEOPLE_CALIBRATION", "HogPeopleConfig", "HogPeopleDetector"]

_WINDOW = (64, 128)  # width, height of the detection window in pixels

# Fitted with our calibration command on every frame of PETS09-S2L1 (795) and TUD-Stadtmitte
# (179), the default configuration at SVM threshold -0.5 (4677 positives, 8252 negatives):
#   python -m devtools.calibrate --detector default \
#       --sequences <data>/mot/PETS09-S2L1 <data>/mot/TUD-Stadtmitte --out hog.calibration.json
# p = 0.5 at an SVM score of 0.97.
HOG_PEOPLE_CALIBRATION = LogisticCalibration(
    a=3.19721,
    b=-3.09958,
    source="OpenCV HOG people, upscale 1.5, hit threshold -0.5; fitted on PETS09-S2L1 and "
    "TUD-Stadtmitte (every frame)",
)
"""Score calibration of the default configuration, ``p = 1 / (1 + exp(-(a s + b)))``."""


@dataclass(frozen=True, slots=True)
class HogPeopleConfig:
    """Options of :class:`HogPeopleDetector`.

    Attributes
    ----------
    upscale:
        Enlarge the frame by this factor first; boxes are mapped back to the frame. ``None``
        (default): by the frame's height (its shorter side), :meth:`upscale_for`.
    auto_upscale:
        With ``upscale`` None: the factor to start from, 1.5, at which the calibration and
        ``box_scale`` were fitted (768x576 and 640x480 sequences).
    auto_heights:
        With ``upscale`` None: the range the enlarged frame's height is kept in, by moving
        the factor off ``auto_upscale``. Surveillance frames show people at sizes that scale
        with the frame: in the 480x360 PETS video most are 40-60 px tall and need 2.0 (720
        px; HOTA of the service pipeline 39.1 at 2.0 against 21.9 at 1.5,
        docs/benchmarks-history.md), while in a 1080-px frame the people that need 1.5 (under about
        90 px) are under a twelfth of its height, and the enlarged frame costs 2.5 times as
        much (on PETS09-S2L1 and TUD-Stadtmitte resized to 1080 px, 1.0 matched 1.5's
        detection AP and tracking HOTA: docs/benchmarks-history.md).
    max_upscale:
        The largest automatic factor, 2.0: frames below 360 px (shorter side) stay under 720 px.
    hit_threshold:
        Raw SVM score a window must exceed (OpenCV's ``hitThreshold``, default 0).
    win_stride:
        Window step in pixels of the enlarged frame (OpenCV default 8).
    scale_step:
        Ratio between pyramid scales. OpenCV's default is 1.05; 1.1 halves the levels and
        nearly the time at the same accuracy (detection AP on every 4th frame: PETS09-S2L1
        0.796 against 0.798, TUD-Stadtmitte 0.644 against 0.636; HOTA of the service pipeline
        on the PETS video 39.7 against 39.1, in 45 s instead of 72 s).
    nms_overlap:
        Suppression threshold (0.5).
    nms_criterion:
        How two windows' overlap is measured for suppression: "smaller" (default),
        intersection over the lower-scoring window's area (voc-release5 ``nms.m``), or "iou",
        intersection over union (the DPM's default).
    box_scale:
        ``(width, height)`` of the person box as fractions of the window (see module doc).
    region_heights:
        Default person-height range of :meth:`HogPeopleDetector.detect_region` and
        :meth:`HogPeopleDetector.dense_scores`, as fractions of the region height.
    workers:
        Threads scanning pyramid levels side by side; ``None``: OpenCV's thread count
        (``cv2.getNumThreads()``), as ``detectMultiScale`` uses.
    """

    upscale: float | None = None
    auto_upscale: float = 1.5
    auto_heights: tuple[float, float] = (720.0, 1080.0)
    max_upscale: float = 2.0
    hit_threshold: float = 0.0
    win_stride: int = 8
    scale_step: float = 1.1
    nms_overlap: float = 0.5
    nms_criterion: NmsCriterion = "smaller"
    box_scale: tuple[float, float] = (0.48, 0.73)
    region_heights: tuple[float, float] = (0.4, 1.0)
    workers: int | None = None

    def __post_init__(self) -> None:
        if self.upscale is not None and not (math.isfinite(self.upscale) and self.upscale > 0):
            raise ValueError(f"upscale must be a positive number, got {self.upscale}")
        for name in ("auto_upscale", "max_upscale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")
        low, high = self.auto_heights
        if not (0 < low <= high < math.inf):
            raise ValueError(f"auto_heights must be 0 < low <= high, got {self.auto_heights}")
        if not math.isfinite(self.hit_threshold):
            raise ValueError(f"hit_threshold must be finite, got {self.hit_threshold}")
        if not is_int(self.win_stride) or self.win_stride < 1:
            raise ValueError(f"win_stride must be a positive int, got {self.win_stride}")
        if not (math.isfinite(self.scale_step) and self.scale_step > 1.0):
            raise ValueError(f"scale_step must be > 1, got {self.scale_step}")
        check_nms_options(self.nms_overlap, self.nms_criterion, prefix="nms_")
        if not all(0 < s <= 1 for s in self.box_scale) or len(self.box_scale) != 2:
            raise ValueError(f"box_scale must be two fractions in (0, 1], got {self.box_scale}")
        low, high = self.region_heights
        if not (0 < low <= high):
            raise ValueError(f"region_heights must be 0 < low <= high, got {self.region_heights}")
        if self.workers is not None and (not is_int(self.workers) or self.workers < 1):
            raise ValueError(f"workers must be a positive int or None, got {self.workers}")

    def upscale_for(self, frame_shape: tuple[int, ...]) -> float:
        """The enlargement of a frame of shape ``(H, W, ...)``: ``upscale`` if set, else
        ``auto_upscale`` moved just enough to bring the enlarged height into ``auto_heights``,
        at most ``max_upscale`` (360 px: 2.0; 480-720 px: 1.5; 1080 px: 1.0; 2160 px: 0.5).

        The height that counts is the frame's shorter side: a camera turned on its side for a
        corridor (a 720x1280 frame) sees people at the sizes it saw them at upright (1280x720)
        and has as many pixels to search, so it gets the same factor."""
        if self.upscale is not None:
            return self.upscale
        height = max(min(frame_shape[:2]), 1)
        low, high = self.auto_heights
        return min(max(self.auto_upscale, low / height), high / height, self.max_upscale)


@dataclass(slots=True)
class HogPeopleDetector:
    """OpenCV's HOG people detector behind the :class:`~tracking.detection.base.Detector` API.

    Parameters
    ----------
    config:
        Options.
    calibration:
        Score-to-probability mapping (default: :data:`HOG_PEOPLE_CALIBRATION`).
    """

    config: HogPeopleConfig = field(default_factory=HogPeopleConfig)
    calibration: LogisticCalibration = HOG_PEOPLE_CALIBRATION
    part_names: tuple[str, ...] = ()
    _hog: cv2.HOGDescriptor = field(init=False, repr=False)
    _svm: np.ndarray = field(init=False, repr=False)
    _pool: ThreadPoolExecutor | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # (OpenCV's stubs type the detector as a sequence; it is a float32 array (3781, 1))
        people = cv2.HOGDescriptor.getDefaultPeopleDetector()
        self._svm = np.asarray(people, dtype=np.float64).ravel()
        self._hog = cv2.HOGDescriptor()
        self._hog.setSVMDetector(self._svm.astype(np.float32))
        workers = self.config.workers or cv2.getNumThreads()
        self._pool = ThreadPoolExecutor(workers, "hog-level") if workers > 1 else None

    def _windows(
        self, image: np.ndarray, heights: tuple[float, float] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Windows above the hit threshold (image coordinates) and their raw scores, in the
        order of the levels (largest first): what ``detectMultiScale`` with grouping disabled
        returns on one thread, whatever the number of threads here. With ``heights`` (person
        heights in pixels of ``image``), only the levels whose person height is in that range."""
        scales = _pyramid_scales(image.shape, self.config.scale_step)
        if heights is not None:
            person = self.config.box_scale[1] * _WINDOW[1]
            scales = [s for s in scales if heights[0] <= person * s <= heights[1]]
        if not scales:
            return np.zeros((0, 4)), np.zeros(0)
        if self._pool is None:
            levels = [self._level_windows(image, s) for s in scales]
        else:
            levels = list(self._pool.map(lambda s: self._level_windows(image, s), scales))
        windows, kept = clip_boxes(np.concatenate([w for w, _ in levels]), image.shape)
        return windows, np.concatenate([s for _, s in levels])[kept]

    def _level_windows(self, image: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
        """The windows of one pyramid level (the image shrunk by ``scale``), in image pixels."""
        height, width = image.shape[:2]
        size = (round(width / scale), round(height / scale))
        level = (
            image
            if size == (width, height)
            else cv2.resize(image, size, interpolation=cv2.INTER_LINEAR_EXACT)
        )
        stride = (self.config.win_stride, self.config.win_stride)
        found, scores = self._hog.detect(
            level, hitThreshold=self.config.hit_threshold, winStride=stride, padding=(0, 0)
        )
        corners = np.asarray(found, dtype=np.float64).reshape(-1, 2)
        windows = np.empty((len(corners), 4))
        windows[:, :2] = np.rint(corners * scale)
        windows[:, 2:] = (round(_WINDOW[0] * scale), round(_WINDOW[1] * scale))
        return windows, np.asarray(scores, dtype=np.float64).reshape(-1)

    def _person_boxes(self, windows: np.ndarray) -> np.ndarray:
        """Shrink windows about their centres to the person (``box_scale``)."""
        sw, sh = self.config.box_scale
        out = windows.copy()
        out[:, 0] += windows[:, 2] * (1 - sw) / 2
        out[:, 1] += windows[:, 3] * (1 - sh) / 2
        out[:, 2] *= sw
        out[:, 3] *= sh
        return out

    def _detections(self, boxes: np.ndarray, scores: np.ndarray) -> Detections:
        return Detections(
            boxes=boxes,
            scores=scores,
            probabilities=self.calibration.probability(scores),
            parts=np.zeros((boxes.shape[0], 0, 4)),
            part_names=(),
        )

    def _run(
        self,
        image: np.ndarray,
        offset: tuple[float, float],
        u: float,
        heights: tuple[float, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        big = image if u == 1.0 else cv2.resize(image, None, fx=u, fy=u)
        big_heights = None if heights is None else (heights[0] * u, heights[1] * u)
        windows, scores = self._windows(np.ascontiguousarray(big), big_heights)
        windows = windows / u
        windows[:, 0] += offset[0]
        windows[:, 1] += offset[1]
        keep = nms(windows, scores, self.config.nms_overlap, self.config.nms_criterion)
        return self._person_boxes(windows[keep]), scores[keep]

    def detect(self, frame: np.ndarray) -> Detections:
        """People in the whole frame (RGB or grayscale uint8)."""
        image = _checked_frame(frame)
        boxes, scores = self._run(image, (0.0, 0.0), self.config.upscale_for(image.shape))
        return self._detections(boxes, scores)

    def _crop(
        self, frame: np.ndarray, region: Box, max_height: float
    ) -> tuple[np.ndarray, int, int]:
        """The frame around ``region``, with room for windows of people up to ``max_height``."""
        win_h = max_height / self.config.box_scale[1]
        win_w = win_h * _WINDOW[0] / _WINDOW[1]
        x0 = max(0, math.floor(region.x - win_w / 2 - 8))
        y0 = max(0, math.floor(region.y - win_h / 2 - 8))
        x1 = min(frame.shape[1], math.ceil(region.x + region.w + win_w / 2 + 8))
        y1 = min(frame.shape[0], math.ceil(region.y + region.h + win_h / 2 + 8))
        return frame[y0:y1, x0:x1], x0, y0

    def detect_region(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> Detections:
        """People whose box centre lies in ``region`` (runs the detector on a crop around it)."""
        image = _checked_frame(frame)
        clipped = clip_region(checked_region(region), image.shape)
        if clipped is None:
            return self._detections(np.zeros((0, 4)), np.zeros(0))
        heights = checked_heights(
            tuple(f * clipped.h for f in self.config.region_heights) if heights is None else heights
        )
        crop, x0, y0 = self._crop(image, clipped, heights[1])
        # The factor follows the whole frame, so a region sees people as the full frame does;
        # only the levels whose people fit ``heights`` are scanned (all of them cost more than
        # the whole frame's search when the region is large).
        u = self.config.upscale_for(image.shape)
        boxes, scores = self._run(crop, (x0, y0), u, heights)
        inside = (
            centres_inside(boxes, clipped)
            & (boxes[:, 3] >= heights[0])
            & (boxes[:, 3] <= heights[1])
        )
        return self._detections(boxes[inside], scores[inside])

    def dense_scores(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> DenseScores | None:
        """Raw SVM scores of every window centred in ``region`` at every fitting scale.

        Level ``l`` is the frame scaled by ``upscale / scale_step^l``; its person height is
        ``box_scale[1] * 128 / scale`` pixels and its grid stride ``win_stride / scale``.
        """
        image = _checked_frame(frame)
        clipped = clip_region(checked_region(region), image.shape)
        if clipped is None:
            return None
        low, high = checked_heights(
            tuple(f * clipped.h for f in self.config.region_heights) if heights is None else heights
        )
        sh = self.config.box_scale[1]
        crop, x0, y0 = self._crop(image, clipped, high)
        stride = self.config.win_stride
        out_h, grids, origins, strides = [], [], [], []
        scale = self.config.upscale_for(image.shape)
        while True:
            person_h = sh * _WINDOW[1] / scale
            if person_h > high:
                break
            if low <= person_h:
                grid = self._scale_scores(crop, scale)
                if grid is not None:
                    # window (i, j) at (j stride, i stride) of the scaled crop
                    cx0 = x0 + (_WINDOW[0] / 2) / scale
                    cy0 = y0 + (_WINDOW[1] / 2) / scale
                    step = stride / scale
                    xs = cx0 + np.arange(grid.shape[1]) * step
                    ys = cy0 + np.arange(grid.shape[0]) * step
                    cols = np.flatnonzero((xs >= clipped.x) & (xs <= clipped.x + clipped.w))
                    rows = np.flatnonzero((ys >= clipped.y) & (ys <= clipped.y + clipped.h))
                    if cols.size and rows.size:
                        grids.append(grid[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1])
                        origins.append((xs[cols[0]], ys[rows[0]]))
                        strides.append(step)
                        out_h.append(person_h)
            scale /= self.config.scale_step
        if not grids:
            return None
        order = np.argsort(out_h, kind="stable")
        return DenseScores(
            region=clipped,
            heights=np.asarray(out_h)[order],
            levels=[grids[i] for i in order],
            origins=np.asarray(origins, dtype=np.float64).reshape(-1, 2)[order],
            strides=np.asarray(strides)[order],
        )

    def _scale_scores(self, crop: np.ndarray, scale: float) -> np.ndarray | None:
        """SVM score of every window position of ``crop`` scaled by ``scale``."""
        size = (round(crop.shape[1] * scale), round(crop.shape[0] * scale))
        if size[0] < _WINDOW[0] or size[1] < _WINDOW[1]:
            return None
        scaled = cv2.resize(crop, size, interpolation=cv2.INTER_LINEAR)
        stride = self.config.win_stride
        descriptors = self._hog.compute(scaled, winStride=(stride, stride), padding=(0, 0))
        nx = (size[0] - _WINDOW[0]) // stride + 1
        ny = (size[1] - _WINDOW[1]) // stride + 1
        features = np.asarray(descriptors, dtype=np.float64).reshape(ny * nx, -1)
        return (features @ self._svm[:-1] + self._svm[-1]).reshape(ny, nx)


def _pyramid_scales(shape: tuple[int, ...], step: float) -> list[float]:
    """The shrink factors of ``detectMultiScale``'s levels: ``step**l`` while the shrunk
    image still holds a window (at most 64 levels, OpenCV's ``nlevels``)."""
    height, width = shape[:2]
    scales: list[float] = []
    scale = 1.0
    while (
        len(scales) < 64
        and round(width / scale) >= _WINDOW[0]
        and round(height / scale) >= _WINDOW[1]
    ):
        scales.append(scale)
        scale *= step
    return scales


def _checked_frame(frame: object) -> np.ndarray:
    """``frame`` as OpenCV's HOG takes it; other types are refused rather than guessed at (a
    16-bit frame clipped to 0..255 is white, a 0..1 float frame black: no people, no error)."""
    return np.ascontiguousarray(validate_uint8_frame(frame, "the HOG people detector"))
