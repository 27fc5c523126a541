"""Fit a detector's score calibration on MOTChallenge sequences with ground truth.

    python -m tracking.detection.calibrate --detector dpm --model PATH \\
        --sequences DIR [DIR ...] [--out PATH] [--step N] [--threshold T] [--upscale U]
        [--workers N]
    python -m tracking.detection.calibrate --detector default --sequences DIR ... --out PATH

The detector runs on every ``step``-th frame of each sequence at a threshold below its operating
one (so that the fit sees the scores around it); each detection is labelled by matching it to
the ground truth (:func:`tracking.detection.metrics.match_frame`: IoU >= 0.5 with a ground-truth
box not yet matched, greedily by score), and a logistic ``p = 1 / (1 + exp(-(a s + b)))`` is
fitted to (score, label) by maximum likelihood
(:func:`tracking.detection.calibration.fit_logistic`).
The result is written as JSON, by default beside the model (``<model>.calibration.json``), where
:class:`~tracking.detection.dpm.detector.DpmDetector` finds it.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tracking.detection.calibration import LogisticCalibration, calibration_path, fit_logistic
from tracking.detection.dpm.detector import DpmConfig, DpmDetector
from tracking.detection.hog_people import HogPeopleConfig, HogPeopleDetector
from tracking.detection.metrics import match_frame
from tracking.detection.sequences import MotSequence
from tracking.output_paths import output_file

__all__ = ["calibrate", "main"]

logger = logging.getLogger(__name__)

DPM_THRESHOLD_BELOW_MODEL = 1.0
"""Default calibration threshold of the DPM: the model's ``thresh`` minus this."""
HOG_CALIBRATION_THRESHOLD = -0.5
"""Default SVM hit threshold of the embedded detector while calibrating (operating: 0)."""


def calibrate(
    detector: object,
    sequences: Sequence[MotSequence],
    step: int = 1,
    source: str = "",
) -> tuple[LogisticCalibration, int, int]:
    """Run ``detector.detect`` on the sequences and fit the logistic mapping.

    Returns
    -------
    calibration, positives, negatives
    """
    if step < 1:
        raise ValueError(f"step must be a positive int, got {step}")
    scores, labels = [], []
    for sequence in sequences:
        for index in range(0, len(sequence), step):
            detections = detector.detect(sequence.read_frame(index))  # type: ignore[attr-defined]
            positive = match_frame(detections.boxes, detections.scores, sequence.gt[index])
            scores.append(detections.scores)
            labels.append(positive)
        logger.info("calibration: %s done", sequence.name)
    s = np.concatenate(scores) if scores else np.zeros(0)
    y = np.concatenate(labels) if labels else np.zeros(0, dtype=bool)
    calibration = fit_logistic(s, y, source=source)
    return calibration, int(y.sum()), int((~y).sum())


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m tracking.detection.calibrate",
        description="Fit a detector's score-to-probability calibration on MOTChallenge data.",
    )
    parser.add_argument("--detector", choices=("dpm", "default"), required=True)
    parser.add_argument("--model", type=Path, help="voc-release5 model file (--detector dpm)")
    parser.add_argument("--sequences", type=Path, nargs="+", required=True)
    parser.add_argument(
        "--out", type=Path, help="output JSON (default for dpm: <model>.calibration.json)"
    )
    parser.add_argument("--step", type=int, default=1, help="use every N-th frame (default 1)")
    parser.add_argument("--threshold", type=float, help="detection threshold while fitting")
    parser.add_argument("--upscale", type=float, help="detector upscale (default: its own)")
    parser.add_argument(
        "--workers", type=int, help="DPM level threads (default: OpenCV's thread count)"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        sequences = [MotSequence.open(path) for path in args.sequences]
        if args.detector == "dpm":
            if args.model is None:
                raise ValueError("--detector dpm needs --model PATH")
            probe = DpmDetector.from_file(args.model)
            threshold = (
                args.threshold
                if args.threshold is not None
                else probe.model.threshold - DPM_THRESHOLD_BELOW_MODEL
            )
            options = {"threshold": threshold, "workers": args.workers}
            if args.upscale is not None:
                options["upscale"] = args.upscale
            detector: object = DpmDetector(probe.model, DpmConfig(**options))
            out = output_file(args.out or calibration_path(args.model))
            what = f"DPM {args.model.name}, threshold {threshold:g}"
        else:
            options = {
                "hit_threshold": args.threshold
                if args.threshold is not None
                else HOG_CALIBRATION_THRESHOLD
            }
            if args.upscale is not None:
                options["upscale"] = args.upscale
            detector = HogPeopleDetector(HogPeopleConfig(**options))
            if args.out is None:
                raise ValueError("--detector default needs --out PATH")
            out = output_file(args.out)
            what = f"OpenCV HOG people, hit threshold {options['hit_threshold']:g}"
        names = ", ".join(s.name for s in sequences)
        frames = "every frame" if args.step == 1 else f"1 frame in {args.step}"
        source = f"{what}; fitted on {names} ({frames})"
        calibration, positives, negatives = calibrate(detector, sequences, args.step, source)
        calibration.save(out)
    except (ValueError, OSError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(
        f"a = {calibration.a:.6g}, b = {calibration.b:.6g} "
        f"({positives} positives, {negatives} negatives) -> {out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
