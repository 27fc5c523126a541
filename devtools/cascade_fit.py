"""Fit the star cascade's thresholds on positive examples: people with ground-truth boxes.

    python -m devtools.cascade_fit --model PATH --sequences DIR [DIR ...]
        [--step N] [--out PATH]

The sequences are OTB-layout folders (``img/`` and ``groundtruth_rect.txt``) whose target is a
whole person. For every ``step``-th frame, the crop around the ground-truth box is scaled so
that the person is 80, 110, 150 or 200 pixels tall (in turn, so that every octave of the
pyramid sees positives) and scored exactly on the pyramid levels whose windows are 0.6 to 2
times that tall. The best-scoring root whose detection window overlaps the box by IoU >= 0.5
is the positive (the latent placement of the paper's training examples); the cascade in
recording mode gives its partial score after every stage and its deformation margins
(:mod:`.cascade`).

For each detection threshold of :data:`SCORE_GRID`, the thresholds are the lowest partial
scores and margins of the positives that score above it (Felzenszwalb et al., CVPR 2010,
§4: "probably approximately admissible"). They are written as JSON, by default beside the
model (``<model>.cascade.json``), where :class:`~.detector.DpmDetector` finds them.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from tracking.datasets.otb import OtbSequence, load_otb_sequence, read_frame
from tracking.detection.dpm.boxes import root_windows
from tracking.detection.dpm.cascade import (
    CascadeThresholds,
    PcaProjection,
    cascade_level,
    cascade_path,
    pca_projection,
)
from tracking.detection.dpm.detector import DpmDetector
from tracking.detection.dpm.model import DpmModel, load_dpm_model
from tracking.detection.dpm.pyramid import level_features
from tracking.detection.dpm.scoring import score_level
from tracking.detection.nms import box_iou
from tracking.output_paths import output_file

__all__ = ["SCORE_GRID", "fit_records", "main", "record_positive", "save_cascade", "thresholds_for"]

logger = logging.getLogger(__name__)

SCORE_GRID = tuple(round(-2.0 + 0.1 * i, 1) for i in range(26))
"""Detection thresholds (-2.0 .. 0.5) the cascade thresholds are tabulated for."""
PERSON_HEIGHTS = (80, 110, 150, 200)
MIN_IOU = 0.5

Record = tuple[float, np.ndarray, np.ndarray]
"""A positive's exact score, partial score after every stage and deformation margins."""


def record_positive(
    detector: DpmDetector,
    image: np.ndarray,
    box: tuple[float, float, float, float],
    projection: PcaProjection | None = None,
) -> Record | None:
    """Exact score, stage partial scores and margins of the best root on ``box`` in ``image``.

    ``projection``: the model's (:func:`.cascade.pca_projection`; computed if not given).
    ``None`` when no root window overlaps the box by IoU >= 0.5.
    """
    model = detector.model
    projection = projection or pca_projection(model)
    pad = detector.pad
    height = box[3]
    best: tuple[float, object, tuple[int, int, int]] | None = None
    for root, needed in detector.search_levels(image.shape, (0.6 * height, 2.0 * height)):
        features = level_features(image, needed, pad)
        scores = score_level(model, features, root, pad, window=detector.config.deformation_window)
        if scores is None:
            continue
        for ci in range(len(model.components)):
            ys, xs = np.nonzero(np.isfinite(scores.component_scores[ci]))
            windows = root_windows(model, scores, ys, xs, np.full(ys.size, ci), pad)
            overlap = box_iou(windows, np.array([box]))[:, 0]
            ok = np.flatnonzero(overlap >= MIN_IOU)
            if ok.size == 0:
                continue
            values = scores.component_scores[ci, ys[ok], xs[ok]]
            k = int(np.argmax(values))
            if best is None or values[k] > best[0]:
                best = (float(values[k]), (root, features), (ci, int(ys[ok[k]]), int(xs[ok[k]])))
    if best is None:
        return None
    score, (root, features), (ci, row, col) = best
    projected = {k: projection.project(v) for k, v in features.items()}
    result = cascade_level(
        model,
        features,
        projected,
        projection,
        root,
        pad,
        CascadeThresholds.exact(model.num_parts),
        -math.inf,
        window=detector.config.deformation_window or 4,
        positions=np.array([[row, col]]),
    )
    assert result is not None
    stages, margins = result[1][ci]
    if stages.shape[0] != 1:
        return None
    return score, stages[0], margins[0]


def _scaled_crop(
    image: np.ndarray, box: tuple[float, float, float, float], height: float
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The box and one box size around it, scaled so that the box is ``height`` tall."""
    x, y, w, h = box
    x0, y0 = max(0, math.floor(x - w)), max(0, math.floor(y - h / 2))
    x1 = min(image.shape[1], math.ceil(x + 2 * w))
    y1 = min(image.shape[0], math.ceil(y + 1.5 * h))
    factor = height / h
    crop = image[y0:y1, x0:x1]
    size = (max(1, round(crop.shape[1] * factor)), max(1, round(crop.shape[0] * factor)))
    interpolation = cv2.INTER_AREA if factor < 1 else cv2.INTER_LINEAR
    scaled = cv2.resize(crop, size, interpolation=interpolation)
    return scaled, ((x - x0) * factor, (y - y0) * factor, w * factor, h * factor)


def fit_records(
    detector: DpmDetector, sequences: Sequence[OtbSequence], step: int = 4
) -> list[Record]:
    """Records of the positives of every ``step``-th frame of the OTB sequences."""
    if step < 1:
        raise ValueError(f"step must be a positive int, got {step}")
    projection = pca_projection(detector.model)
    records = []
    turn = 0
    for sequence in sequences:
        for index in range(0, len(sequence), step):
            box = tuple(float(v) for v in sequence.ground_truth[index])
            if not (np.all(np.isfinite(box)) and box[2] > 0 and box[3] > 0):
                continue
            image = read_frame(sequence.frame_paths[index])
            crop, scaled_box = _scaled_crop(image, box, PERSON_HEIGHTS[turn % len(PERSON_HEIGHTS)])
            turn += 1
            record = record_positive(detector, crop, scaled_box, projection)
            if record is not None:
                records.append(record)
        logger.info("%s: %d positives so far", sequence.name, len(records))
    return records


def thresholds_for(records: Sequence[Record], score_threshold: float) -> CascadeThresholds | None:
    """PAA thresholds from the positives scoring above ``score_threshold`` (None: none do)."""
    kept = [r for r in records if r[0] > score_threshold]
    if not kept:
        return None
    stages = np.array([r[1] for r in kept])
    margins = np.array([r[2] for r in kept])
    margins = np.where(np.isnan(margins), -np.inf, margins)
    return CascadeThresholds(score_threshold, stages.min(axis=0), margins.min(axis=0))


def save_cascade(
    path: Path,
    model: DpmModel,
    records: Sequence[Record],
    source: str,
) -> Path:
    """Write the thresholds of every :data:`SCORE_GRID` entry some positive scores above."""
    table = []
    for value in SCORE_GRID:
        t = thresholds_for(records, value)
        if t is not None:
            table.append(
                {
                    "score_threshold": value,
                    "positives": int(sum(r[0] > value for r in records)),
                    "stage": [round(float(v), 4) for v in t.stage],
                    "deformation": [
                        None if not np.isfinite(v) else round(float(v), 4) for v in t.deformation
                    ],
                }
            )
    rows = ",\n  ".join(json.dumps(row) for row in table)  # one line per detection threshold
    head = json.dumps({"model": model.name, "components": len(model.components), "source": source})
    path.write_text(f'{head[:-1]}, "thresholds": [\n  {rows}\n]}}\n')
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m devtools.cascade_fit", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--model", required=True, help="voc-release5 model file (.mat)")
    parser.add_argument(
        "--sequences",
        nargs="+",
        required=True,
        help="OTB-layout folders (img/ and groundtruth_rect.txt) whose target is a person",
    )
    parser.add_argument("--step", type=int, default=4, help="every N-th frame (default 4)")
    parser.add_argument("--out", help="default: <model>.cascade.json beside the model")
    args = parser.parse_args(argv)
    if args.step < 1:
        parser.error("--step must be a positive int")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        model = load_dpm_model(args.model)
        # every folder is read, and the output checked, before the minutes of fitting start
        sequences = [load_otb_sequence(folder) for folder in args.sequences]
        out = output_file(args.out or cascade_path(args.model))
        records = fit_records(DpmDetector(model), sequences, args.step)
        if not records:
            raise ValueError("no positive example found (no root window on a ground-truth box)")
        names = ", ".join(s.name for s in sequences)
        source = f"{len(records)} positives from {names}, 1 frame in {args.step}"
        save_cascade(out, model, records, source)
    except (ValueError, OSError) as error:  # a bad model file or folder, an unwritable output
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"{source}; written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
