"""Options of the DPM detector (:class:`tracking.detection.dpm.detector.DpmDetector`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from tracking.detection.nms import NmsCriterion, check_nms_options
from tracking.types import is_int

__all__ = ["DPM_TRACKING_CONFIG", "DpmConfig"]


@dataclass(frozen=True, slots=True)
class DpmConfig:
    """Options of :class:`~tracking.detection.dpm.detector.DpmDetector`.

    Attributes
    ----------
    threshold:
        Raw score above which a root position is a detection; ``None``: the model's
        ``thresh`` (INRIA: -0.126, voc-release5's default).
    upscale:
        Enlarge the frame by this factor before building the pyramid (1: voc-release5). The
        smallest window the INRIA model finds is 15 cells of ``sbin / 2`` = 60 px tall at 1;
        2.0 halves that. ``None`` (default): by the frame's height (its shorter side),
        :meth:`upscale_for`.
    auto_max_height:
        With ``upscale`` None: frames up to this many pixels high (shorter side) are searched
        as they are, taller ones shrunk to it (a 4K frame by half). The cost grows with the
        pixels, and people in such frames are far above the smallest window: on PETS09-S2L1
        enlarged to 2160 px, half size finds them as well as full size at a quarter of the time
        (``docs/benchmarks-history.md``).
    levels_per_octave:
        Pyramid levels per octave; ``None``: the model's ``interval`` (10). Fewer levels are
        proportionally faster and sample scale more coarsely (5: steps of 15% in size).
    min_height, max_height:
        Search only pyramid levels whose detection-window height (pixels of the input frame)
        lies in this range; ``None``: no limit (all levels of voc-release5's pyramid).
    deformation_window:
        Largest part displacement from its anchor in cells (voc-release5 ``bounded_dt``: 4);
        ``None``: unbounded, the exact linear-time distance transform.
    nms_overlap:
        Non-maximum suppression threshold: 0.5, as voc-release5 (which measures it over the
        smaller box) and the usual IoU suppression.
    nms_criterion:
        How two boxes' overlap is measured for suppression: "iou" (default), intersection over
        union, or "smaller", intersection over the lower-scoring box's area (voc-release5
        ``nms.m``). "smaller" suppresses a person standing half in front of a higher-scoring
        neighbour, or inside a higher-scoring box around a group; "iou" keeps them. On every
        frame of PETS09-S2L1 and TUD-Stadtmitte the INRIA model's AP is 0.874 / 0.838 with
        IoU 0.5 against 0.845 / 0.774 with release 5's suppression (``docs/benchmarks-history.md``).
    bbox_prediction:
        Refine boxes with the model's bounding-box regression (``bboxpred``).
    max_candidates:
        Keep at most this many best-scoring positions before suppression (bounds the work at
        very low thresholds).
    region_heights:
        Default window-height range for :meth:`DpmDetector.detect_region` and
        :meth:`DpmDetector.dense_scores`, as fractions of the region's height.
    workers:
        Threads that compute pyramid levels concurrently (the compiled kernels and OpenCV
        release the GIL), from one pool per detector; ``None`` (default): OpenCV's thread
        count (``cv2.getNumThreads()``, the cores unless ``cv2.setNumThreads`` or
        ``OPENCV_FOR_THREADS_NUM`` says otherwise), as the embedded detector does. The
        detections are the same whatever the count. The kernels make no BLAS call, so BLAS's
        own threads cannot oversubscribe the cores under them; only a model the kernels cannot
        score (``kernels_apply``) goes through BLAS products, and wants
        ``OPENBLAS_NUM_THREADS=1`` with ``workers > 1``.
    calibration:
        JSON calibration file; ``None``: ``<model>.calibration.json`` beside the model if it
        exists, else the detector module's ``DEFAULT_DPM_CALIBRATION``.
    cascade:
        Score whole frames and regions of interest (their levels with 225 root positions or
        more) with the star cascade (:mod:`.cascade`) when thresholds fitted for the model and
        for a detection threshold at or below ``threshold`` exist: the same scores for the
        roots it keeps, several times faster, but a person scoring lower at some stage than
        every positive the thresholds were fitted on is lost. Needs a bounded
        ``deformation_window``. Dense scores always score exactly.
    cascade_thresholds:
        JSON thresholds file (``python -m devtools.cascade_fit``); ``None``:
        ``<model>.cascade.json`` beside the model if it exists, else the thresholds shipped for
        the voc-release5 INRIA person model (``KNOWN_CASCADES``), else no cascade.
    """

    threshold: float | None = None
    upscale: float | None = None
    auto_max_height: int = 1080
    levels_per_octave: int | None = None
    min_height: float | None = None
    max_height: float | None = None
    deformation_window: int | None = 4
    nms_overlap: float = 0.5
    nms_criterion: NmsCriterion = "iou"
    bbox_prediction: bool = True
    max_candidates: int = 5000
    region_heights: tuple[float, float] = (0.4, 1.0)
    workers: int | None = None
    calibration: Path | None = None
    cascade: bool = True
    cascade_thresholds: Path | None = None

    def __post_init__(self) -> None:
        if self.threshold is not None and math.isnan(self.threshold):  # would detect nothing
            raise ValueError("threshold must be a number or None, got nan")
        if self.upscale is not None and not (math.isfinite(self.upscale) and self.upscale > 0):
            raise ValueError(f"upscale must be a positive number or None, got {self.upscale}")
        if not is_int(self.auto_max_height) or self.auto_max_height < 1:
            raise ValueError(f"auto_max_height must be a positive int, got {self.auto_max_height}")
        for name in ("min_height", "max_height"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number or None, got {value}")
        if (
            self.min_height is not None
            and self.max_height is not None
            and self.min_height > self.max_height
        ):
            raise ValueError(
                f"min_height must not exceed max_height, got {self.min_height} > {self.max_height}"
            )
        levels = self.levels_per_octave
        if levels is not None and not is_int(levels):
            raise ValueError(f"levels_per_octave must be a positive int or None, got {levels}")
        if levels is not None and levels < 1:
            raise ValueError(f"levels_per_octave must be positive, got {levels}")
        window = self.deformation_window
        if window is not None and not is_int(window):
            raise ValueError(f"deformation_window must be a non-negative int or None, got {window}")
        if window is not None and window < 0:
            raise ValueError(f"deformation_window must be non-negative, got {window}")
        check_nms_options(self.nms_overlap, self.nms_criterion, prefix="nms_")
        if self.workers is not None and (not is_int(self.workers) or self.workers < 1):
            raise ValueError(f"workers must be a positive int or None, got {self.workers}")
        if self.max_candidates < 1:
            raise ValueError(f"max_candidates must be positive, got {self.max_candidates}")
        low, high = self.region_heights
        if not (0 < low <= high):
            raise ValueError(f"region_heights must be 0 < low <= high, got {self.region_heights}")

    def upscale_for(self, frame_shape: tuple[int, ...]) -> float:
        """The enlargement of a frame of shape ``(H, W, ...)``: ``upscale`` if set, else 1 up
        to ``auto_max_height`` and ``auto_max_height / H`` above it (1080 px: 1.0; 2160 px:
        0.5), with ``H`` the frame's shorter side (a portrait frame as its landscape
        counterpart: see ``HogPeopleConfig.upscale_for``)."""
        if self.upscale is not None:
            return self.upscale
        return min(1.0, self.auto_max_height / max(min(frame_shape[:2]), 1))


DPM_TRACKING_CONFIG = DpmConfig(threshold=-0.7, nms_criterion="iou", nms_overlap=0.3)
"""The DPM's operating point for tracking people (the service and ``benchmarks/mot.py`` use it).

The voc-release5 defaults are tuned for average precision on single images. A tracker also
wants the weaker detections near people it already follows (it never starts a track on one below
its ``birth_confidence``, so they only carry tracks through hard frames), and it wants people
in a group kept: intersection over the smaller box suppresses a person standing half in front
of a neighbour or inside a higher-scoring window around the group, intersection over union
keeps them. Chosen on PETS09-S2L1 and TUD-Stadtmitte (``docs/benchmarks.md``).
"""
