"""CNN person detectors on OpenVINO behind the :class:`~tracking.detection.base.Detector` API.

A frame goes to the network whole, at its own aspect (:meth:`CnnConfig.input_for
<tracking.detection.cnn.config.CnnConfig.input_for>`); a region of interest goes as a square
crop around it, and the regions of one frame go as one batch (:meth:`CnnDetector.detect_regions`,
which the people tracker's scheduler uses between full searches). Outputs are decoded by family
(:mod:`.decoders`), suppressed by IoU, and scored:

- ``scores`` are the network confidence's log-odds, ``log(c / (1 - c))``, so that the logistic
  calibration ``p = sigma(a s + b)`` is Platt scaling of the network's logit (a temperature
  ``a`` and a bias ``b``), fitted with ``python -m devtools.calibrate --detector cnn``;
- ``probabilities`` are the calibrated ones.

The networks find people, not their parts (``part_names == ()``), and score no dense maps
(:meth:`CnnDetector.dense_scores` returns ``None``: the tracker's likelihood then comes from the
detections).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np

from tracking.detection.base import DenseScores, Detections
from tracking.detection.calibration import LogisticCalibration, calibration_path, load_calibration
from tracking.detection.cnn.config import CnnConfig
from tracking.detection.cnn.decoders import decode_ssd, decode_yolox
from tracking.detection.cnn.runtime import CnnModelError, Network, load_network
from tracking.detection.nms import nms
from tracking.detection.regions import (
    centres_inside,
    checked_heights,
    checked_region,
    clip_boxes,
    clip_region,
)
from tracking.types import Box, validate_uint8_frame

__all__ = ["KNOWN_CALIBRATIONS", "CnnDetector"]

# Each fitted with our calibration command on 1 frame in 2 of PETS09-S2L1 and TUD-Stadtmitte
# (488 frames), the CnnConfig defaults (input at the frame's aspect, 768x576 for both: TUD's
# 640x480 enlarged to 576 px) and confidence >= 0.05 while fitting, e.g. for 0202:
#   python -m devtools.calibrate --detector cnn \
#       --model <data>/models/person-detection-0202/FP16/person-detection-0202.xml \
#       --sequences <data>/mot/PETS09-S2L1 <data>/mot/TUD-Stadtmitte --step 2 --out <file>
# (the others with their own --model; --out since the shared model folder is read-only).
# Scores are the confidence's log-odds, so ``a`` is a temperature and ``b`` a bias of it.
KNOWN_CALIBRATIONS: Mapping[str, LogisticCalibration] = MappingProxyType(
    {
        # 2714 positives, 1402 negatives; p = 0.16 at the default threshold (confidence 0.2),
        # 0.43 at 0.5, 0.87 at 0.9; p = 0.5 at confidence 0.58.
        "person-detection-0202": LogisticCalibration(
            a=0.987241,
            b=-0.303529,
            source="CNN person-detection-0202.xml, confidence >= 0.05; fitted on PETS09-S2L1, "
            "TUD-Stadtmitte (1 frame in 2)",
        ),
        # 2723 positives, 7659 negatives; p = 0.14 at confidence 0.2, 0.53 at 0.5, 0.96 at
        # 0.9; p = 0.5 at confidence 0.48.
        "person-detection-0200": LogisticCalibration(
            a=1.40351,
            b=0.127377,
            source="CNN person-detection-0200.xml, confidence >= 0.05; fitted on PETS09-S2L1, "
            "TUD-Stadtmitte (1 frame in 2)",
        ),
        # 2778 positives, 3406 negatives; p = 0.06 at confidence 0.2, 0.19 at 0.5, 0.67 at
        # 0.9; p = 0.5 at confidence 0.82 (its false positives are confident).
        "person-detection-retail-0013": LogisticCalibration(
            a=0.994592,
            b=-1.47222,
            source="CNN person-detection-retail-0013.xml, confidence >= 0.05; fitted on "
            "PETS09-S2L1, TUD-Stadtmitte (1 frame in 2)",
        ),
        # 2672 positives, 3629 negatives; p = 0.02 at confidence 0.2, 0.26 at 0.5, 0.98 at
        # 0.9; p = 0.5 at confidence 0.62 (objectness times class score: steeper).
        "yolox_nano": LogisticCalibration(
            a=2.20632,
            b=-1.03023,
            source="CNN yolox_nano.onnx, confidence >= 0.05; fitted on PETS09-S2L1, "
            "TUD-Stadtmitte (1 frame in 2)",
        ),
    }
)
"""Calibrations of the models we measured, by model name (the file's stem)."""

_MAX_BATCH = 16  # regions per inference; batches are padded to a power of two (few shapes)
_LETTERBOX_FILL = {"ssd": 0, "yolox": 114}  # the YOLOX demo pads with grey 114


@dataclass(slots=True)
class CnnDetector:
    """A CNN person detector.

    Parameters
    ----------
    network:
        The loaded model (:func:`~tracking.detection.cnn.runtime.load_network`).
    config:
        Options.
    calibration:
        Score-to-probability mapping; ``None``: found as ``config.calibration`` says.
    """

    network: Network
    config: CnnConfig = field(default_factory=CnnConfig)
    calibration: LogisticCalibration | None = None
    part_names: tuple[str, ...] = ()
    family: str = field(init=False)

    def __post_init__(self) -> None:
        family: str = self.config.family
        if family == "auto":
            family = {4: "ssd", 3: "yolox"}.get(self.network.output_rank, "")
        expected = {"ssd": 4, "yolox": 3}.get(family)
        if expected != self.network.output_rank:
            raise CnnModelError(
                f"{self.network.path.name}'s output has {self.network.output_rank} dimensions: "
                "not an SSD detection output [1, 1, N, 7] nor a YOLOX head [1, A, 5 + classes]"
            )
        self.family = family
        if self.calibration is None:
            self.calibration = _find_calibration(self.network.path, self.config)

    @classmethod
    def from_file(
        cls, path: str | os.PathLike[str], config: CnnConfig | None = None
    ) -> CnnDetector:
        """Load the model at ``path`` (``.xml`` IR or ``.onnx``); raises ``CnnModelError``."""
        config = config or CnnConfig()
        return cls(load_network(path, config.threads), config)

    @property
    def model_name(self) -> str:
        """The model's name (its file's stem)."""
        return self.network.name

    # -- full frames ------------------------------------------------------------------------

    def detect(self, frame: np.ndarray) -> Detections:
        """People in the whole frame (RGB or greyscale uint8)."""
        image = _bgr(frame)
        if self.network.reshapeable:
            size = self.config.input_for(image.shape)
            blob = cv2.resize(image, size, interpolation=_interpolation(image.shape, size))
            scale = (size[0] / image.shape[1], size[1] / image.shape[0])
            batch = np.empty((1, 3, size[1], size[0]), dtype=np.float32)
            batch[0] = blob.transpose(2, 0, 1)  # planar float in one pass, contiguous
        else:
            batch, s = self._letterboxed([image])
            scale = (s[0], s[0])
        ((corners, confidence),) = self._decode(self.network.infer(batch), batch.shape)
        corners = corners / np.array(scale * 2)
        return self._detections(corners, confidence, image.shape)

    # -- regions of interest ----------------------------------------------------------------

    def detect_region(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> Detections:
        """People whose box centre lies in ``region`` and whose height is in ``heights``."""
        return self.detect_regions(frame, [(region, heights)])[0]

    def detect_regions(
        self,
        frame: np.ndarray,
        regions: Sequence[tuple[Box, tuple[float, float] | None]],
    ) -> list[Detections]:
        """:meth:`detect_region` for each ``(region, heights)``, in batched inferences.

        Each region is searched as a square crop of side ``max(w, h, 1.25 * max height)``
        around its centre, resized to ``region_input`` pixels (enlarged at most
        ``max_upscale`` times as much as the full frame would be).
        """
        image = _bgr(frame)
        jobs, out = (
            [],
            [self._detections(np.zeros((0, 4)), np.zeros(0), image.shape)] * len(regions),
        )
        for index, (region, heights) in enumerate(regions):
            clipped = clip_region(checked_region(region), image.shape)
            if clipped is None:
                continue
            heights = checked_heights(
                tuple(f * clipped.h for f in self.config.region_heights)
                if heights is None
                else heights
            )
            side = max(clipped.w, clipped.h, 1.25 * heights[1])
            x0 = max(0, math.floor(clipped.x + clipped.w / 2 - side / 2))
            y0 = max(0, math.floor(clipped.y + clipped.h / 2 - side / 2))
            x1 = min(image.shape[1], math.ceil(x0 + side))
            y1 = min(image.shape[0], math.ceil(y0 + side))
            jobs.append((index, clipped, heights, image[y0:y1, x0:x1], (x0, y0)))
        # a model of fixed shape takes its own batch size (1 for those we know)
        per_batch = _MAX_BATCH if self.network.reshapeable else self.network.input_shape[0]
        for start in range(0, len(jobs), per_batch):
            chunk = jobs[start : start + per_batch]
            crops = [crop for _, _, _, crop, _ in chunk]
            limit = self.config.max_upscale * self.config.input_scale(image.shape)
            batch, scales = self._letterboxed(crops, self.config.region_input, limit)
            decoded = self._decode(self.network.infer(batch), batch.shape)
            for (index, clipped, heights, _, (x0, y0)), (corners, confidence), s in zip(
                chunk, decoded, scales, strict=False
            ):
                corners = corners / s + np.array([x0, y0, x0, y0])
                found = self._detections(corners, confidence, image.shape)
                boxes = found.boxes
                keep = (
                    centres_inside(boxes, clipped)
                    & (boxes[:, 3] >= heights[0])
                    & (boxes[:, 3] <= heights[1])
                )
                out[index] = found.subset(keep)
        return out

    def dense_scores(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> DenseScores | None:
        """``None``: the networks score boxes, not every position (the tracker then builds its
        likelihood from the detections)."""
        return None

    # -- shared steps -----------------------------------------------------------------------

    def _letterboxed(
        self, images: list[np.ndarray], side: int | None = None, max_scale: float = math.inf
    ) -> tuple[np.ndarray, list[float]]:
        """``images`` resized at their aspect into one batch (top-left, the rest filled), and
        each one's scale. A reshapeable model gets a square input of ``side`` (default: its
        own height) and a batch padded to a power of two; another model its own input."""
        n, _, height, width = self.network.input_shape
        if self.network.reshapeable:
            height = width = side or height
            n = 1 << (len(images) - 1).bit_length()
        batch = np.full((n, height, width, 3), _LETTERBOX_FILL[self.family], dtype=np.float32)
        scales = []
        for i, image in enumerate(images):
            s = min(width / image.shape[1], height / image.shape[0], max_scale)
            size = (max(1, round(image.shape[1] * s)), max(1, round(image.shape[0] * s)))
            batch[i, : size[1], : size[0]] = cv2.resize(
                image, size, interpolation=_interpolation(image.shape, size)
            )
            scales.append(s)
        return np.ascontiguousarray(batch.transpose(0, 3, 1, 2)), scales

    def _decode(
        self, output: np.ndarray, batch_shape: tuple[int, ...]
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """Corners in input pixels and confidences, per image of the batch."""
        n, _, height, width = batch_shape
        if self.family == "yolox":
            return decode_yolox(output, (width, height), self.config.class_id)
        return [
            (corners * np.array([width, height, width, height]), confidence)
            for corners, confidence in decode_ssd(output, n, self.config.ssd_label)
        ]

    def _detections(
        self, corners: np.ndarray, confidence: np.ndarray, shape: tuple[int, ...]
    ) -> Detections:
        """Detections from corners ``(K, 4)`` in frame pixels: thresholded, clipped to the
        frame, suppressed."""
        chosen = confidence >= self.config.threshold
        corners, confidence = corners[chosen], confidence[chosen]
        boxes = np.column_stack([corners[:, :2], corners[:, 2:] - corners[:, :2]])
        boxes, kept = clip_boxes(boxes.reshape(-1, 4), shape)
        confidence = confidence[kept]
        keep = nms(boxes, confidence, self.config.nms_overlap, self.config.nms_criterion)
        c = np.clip(confidence[keep], 1e-6, 1 - 1e-6)
        scores = np.log(c / (1 - c))
        calibration = self.calibration
        return Detections(
            boxes=boxes[keep],
            scores=scores,
            probabilities=c if calibration is None else calibration.probability(scores),
            parts=np.zeros((len(keep), 0, 4)),
            part_names=(),
        )


def _bgr(frame: object) -> np.ndarray:
    """The frame as the networks take it: BGR, three channels (a greyscale frame repeated)."""
    image = validate_uint8_frame(frame, "the CNN detector")
    code = cv2.COLOR_GRAY2BGR if image.ndim == 2 else cv2.COLOR_RGB2BGR
    return cv2.cvtColor(image, code)


def _interpolation(shape: tuple[int, ...], size: tuple[int, int]) -> int:
    """Area averaging to shrink (no aliasing), bilinear to enlarge."""
    return cv2.INTER_AREA if size[0] < shape[1] else cv2.INTER_LINEAR


def _find_calibration(path: Path, config: CnnConfig) -> LogisticCalibration | None:
    if config.calibration is not None:
        return load_calibration(config.calibration)
    beside = calibration_path(path)
    if beside.is_file():
        return load_calibration(beside)
    return KNOWN_CALIBRATIONS.get(path.stem)
