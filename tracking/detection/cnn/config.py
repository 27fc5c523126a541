"""Options of the CNN person detector (:class:`tracking.detection.cnn.detector.CnnDetector`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from tracking.detection.nms import NmsCriterion, check_nms_options
from tracking.types import is_int

__all__ = ["CnnConfig", "ModelFamily", "check_input_rule", "input_scale_for", "input_size_for"]

ModelFamily = Literal["auto", "ssd", "yolox"]
"""How a model's output is decoded; "auto" tells them by the output's rank (SSD 4, YOLOX 3)."""


@dataclass(frozen=True, slots=True)
class CnnConfig:
    """Options of :class:`~tracking.detection.cnn.detector.CnnDetector`.

    Attributes
    ----------
    family:
        The model's output format (see :mod:`.decoders`); "auto" by default.
    threshold:
        Confidence (the network's own, in ``[0, 1]``) a box must reach to be a detection.
    nms_overlap, nms_criterion:
        Suppression of overlapping boxes after decoding: intersection over union 0.45, the
        YOLOX demo's (SSD networks suppress inside; this pass also merges region crops).
    upscale:
        Resize the frame by this factor (its aspect kept); ``None`` (default): by its height,
        :meth:`input_scale`.
    input_size:
        ``(width, height)`` the frame is resized to, overriding ``upscale``; ``None``
        (default): the frame's own aspect at the size :meth:`input_scale` gives, for models
        that can be reshaped (Open Model Zoo SSDs and YOLOX export with a static but changeable
        shape); a model that cannot is fed at its own size, the frame letterboxed into it.
    input_heights:
        With ``input_size`` None: the range the input's height (the frame's shorter side,
        scaled) is kept in. A frame in it is fed at its own size; a smaller one is enlarged
        (people in a 360-px frame are 40-60 px tall, where the detectors start to miss them),
        a larger one shrunk (a 4K frame's people are large, and its pixels cost 9 times a
        720p frame's).
    max_upscale:
        The largest enlargement.
    stride:
        The input's sides are multiples of this (the networks' coarsest stride, 32).
    region_input:
        Side in pixels of the square input a region of interest is searched at. The tracker's
        regions are about twice a person's height (its margin of half a box on each side), so
        192 shows the person about 96 px tall, in the range the detectors find best: on
        PETS09-S2L1's people (every 40th frame, regions from the ground truth) recall 0.95-0.96
        against 0.97 at 256 and 0.90 at 128, in 0.6-0.7 of 256's time.
    region_heights:
        Default person-height range of a region search, as fractions of the region height.
    ssd_label:
        SSD rows of this class only; ``None``: every row (the person detectors have one class).
    class_id:
        YOLOX class whose boxes are people (COCO: 0).
    threads:
        Inference threads; 0: OpenVINO's choice (every core).
    calibration:
        JSON calibration file; ``None``: ``<model>.calibration.json`` beside the model if it
        exists, else the model's entry in ``KNOWN_CALIBRATIONS``, else the network's confidence.
    """

    family: ModelFamily = "auto"
    threshold: float = 0.2
    nms_overlap: float = 0.45
    nms_criterion: NmsCriterion = "iou"
    upscale: float | None = None
    input_size: tuple[int, int] | None = None
    input_heights: tuple[float, float] = (576.0, 1080.0)
    max_upscale: float = 2.0
    stride: int = 32
    region_input: int = 192
    region_heights: tuple[float, float] = (0.4, 1.0)
    ssd_label: int | None = None
    class_id: int = 0
    threads: int = 0
    calibration: Path | None = None

    def __post_init__(self) -> None:
        if self.family not in ("auto", "ssd", "yolox"):
            raise ValueError(f"family must be 'auto', 'ssd' or 'yolox', got {self.family!r}")
        if not (math.isfinite(self.threshold) and 0.0 <= self.threshold < 1.0):
            raise ValueError(f"threshold must be a confidence in [0, 1), got {self.threshold}")
        check_nms_options(self.nms_overlap, self.nms_criterion, prefix="nms_")
        if self.upscale is not None and not (math.isfinite(self.upscale) and self.upscale > 0):
            raise ValueError(f"upscale must be a positive number, got {self.upscale}")
        check_input_rule(self.input_size, self.input_heights, self.max_upscale)
        for name in ("stride", "region_input"):
            if not is_int(getattr(self, name)) or getattr(self, name) < 1:
                raise ValueError(f"{name} must be a positive int, got {getattr(self, name)}")
        low, high = self.region_heights
        if not (0 < low <= high):
            raise ValueError(f"region_heights must be 0 < low <= high, got {self.region_heights}")
        if not is_int(self.threads) or self.threads < 0:
            raise ValueError(f"threads must be an int >= 0, got {self.threads}")

    def input_scale(self, frame_shape: tuple[int, ...]) -> float:
        """The factor a frame of shape ``(H, W, ...)`` is resized by: ``upscale`` if set, else
        1 when its shorter side is within ``input_heights``, else just enough to bring it there
        (at most ``max_upscale``): 360 px -> 1.6, 480 px -> 1.2, 576-1080 px -> 1, 2160 px ->
        0.5."""
        if self.upscale is not None:
            return self.upscale
        return input_scale_for(frame_shape, self.input_heights, self.max_upscale)

    def input_for(self, frame_shape: tuple[int, ...]) -> tuple[int, int]:
        """``(width, height)`` of the network input for a frame (a multiple of ``stride``)."""
        if self.input_size is not None:
            return self.input_size
        return input_size_for(frame_shape, self.input_scale(frame_shape), self.stride)


# The input rule the CNN networks share (the person detectors, the pose network): a frame at its
# own aspect, its shorter side brought into a range of heights.


def check_input_rule(
    input_size: tuple[int, int] | None, heights: tuple[float, float], max_upscale: float
) -> None:
    """Raise ``ValueError`` for a fixed ``input_size`` under 32 px, a ``heights`` range that is
    none, or a ``max_upscale`` under 1."""
    if input_size is not None and not (
        len(input_size) == 2 and all(is_int(v) and v >= 32 for v in input_size)
    ):
        raise ValueError(f"input_size must be (width, height) >= 32, got {input_size}")
    low, high = heights
    if not (0 < low <= high < math.inf):
        raise ValueError(f"input_heights must be 0 < low <= high, got {heights}")
    if not (math.isfinite(max_upscale) and max_upscale >= 1.0):
        raise ValueError(f"max_upscale must be >= 1, got {max_upscale}")


def input_scale_for(
    frame_shape: tuple[int, ...], heights: tuple[float, float], max_upscale: float
) -> float:
    """1 when the frame's shorter side is within ``heights``, else the factor that brings it
    to the nearer end, at most ``max_upscale``."""
    side = max(min(frame_shape[:2]), 1)
    low, high = heights
    return min(max(1.0, low / side), high / side, max_upscale)


def input_size_for(frame_shape: tuple[int, ...], scale: float, stride: int) -> tuple[int, int]:
    """``(width, height)`` of a frame of shape ``(H, W, ...)`` scaled by ``scale``, each side
    rounded to a multiple of ``stride`` (halves up, not to even)."""
    height, width = frame_shape[:2]
    return (
        max(stride, math.floor(width * scale / stride + 0.5) * stride),
        max(stride, math.floor(height * scale / stride + 0.5) * stride),
    )
