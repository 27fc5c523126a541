"""Fit a detector's score calibration on MOTChallenge sequences with ground truth.

    python -m devtools.calibrate --detector dpm --model PATH \\
        --sequences DIR [DIR ...] [--out PATH] [--step N] [--threshold T] [--upscale U]
        [--workers N]
    python -m devtools.calibrate --detector cnn --model PATH.xml|PATH.onnx \\
        --sequences DIR [DIR ...] [--out PATH] [--step N] [--threshold T] [--workers N]
    python -m devtools.calibrate --detector default --sequences DIR ... --out PATH

The detector runs on every ``step``-th frame of each sequence at a threshold below its operating
one (so that the fit sees the scores around it); each detection is labelled by matching it to
the ground truth (:func:`tracking.evaluation.detection.match_frame`: IoU >= 0.5 with a ground-truth
box not yet matched, greedily by score), and a logistic ``p = 1 / (1 + exp(-(a s + b)))`` is
fitted to (score, label) by maximum likelihood
(:func:`tracking.detection.calibration.fit_logistic`).
The result is written as JSON, by default beside the model (``<model>.calibration.json``), where
:class:`~tracking.detection.dpm.detector.DpmDetector` and
:class:`~tracking.detection.cnn.detector.CnnDetector` find it; a model in a read-only folder (the
shared data's) needs ``--out``, and its fit goes into the code's ``KNOWN_CALIBRATIONS``.

The CNN detector's scores are the log-odds of the network's confidence, so its fit is Platt
scaling of the network's logit; it runs at confidence 0.05 while fitting (operating: 0.2), with
its default input size (the frame's aspect, ``CnnConfig.input_heights``).
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tracking.datasets.mot import MotSequence
from tracking.detection.calibration import LogisticCalibration, calibration_path, fit_logistic
from tracking.detection.cnn import MODEL_SUFFIXES, CnnConfig, CnnDetector, load_network
from tracking.detection.dpm.detector import DpmConfig, DpmDetector
from tracking.detection.hog_people import HogPeopleConfig, HogPeopleDetector
from tracking.evaluation.detection import match_frame
from tracking.output_paths import output_file

__all__ = ["calibrate", "main"]

logger = logging.getLogger(__name__)

DPM_THRESHOLD_BELOW_MODEL = 1.0
"""Default calibration threshold of the DPM: the model's ``thresh`` minus this."""
HOG_CALIBRATION_THRESHOLD = -0.5
"""Default SVM hit threshold of the embedded detector while calibrating (operating: 0)."""
CNN_CALIBRATION_THRESHOLD = 0.05
"""Default network confidence of the CNN detector while calibrating (operating: 0.2)."""


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
        prog="python -m devtools.calibrate",
        description="Fit a detector's score-to-probability calibration on MOTChallenge data.",
    )
    parser.add_argument("--detector", choices=("dpm", "cnn", "default"), required=True)
    parser.add_argument(
        "--model",
        type=Path,
        help="voc-release5 model file (--detector dpm), OpenVINO IR .xml or .onnx (--detector cnn)",
    )
    parser.add_argument("--sequences", type=Path, nargs="+", required=True)
    parser.add_argument(
        "--out",
        type=Path,
        help="output JSON (default for dpm and cnn: <model>.calibration.json beside the model, "
        "if that folder is writable)",
    )
    parser.add_argument("--step", type=int, default=1, help="use every N-th frame (default 1)")
    parser.add_argument(
        "--threshold",
        type=float,
        help="detection threshold while fitting (default: dpm the model's minus "
        f"{DPM_THRESHOLD_BELOW_MODEL:g}, cnn confidence {CNN_CALIBRATION_THRESHOLD:g}, default "
        f"SVM score {HOG_CALIBRATION_THRESHOLD:g})",
    )
    parser.add_argument(
        "--upscale", type=float, help="detector upscale, dpm and default (default: its own)"
    )
    parser.add_argument(
        "--workers",
        type=int,
        help="DPM level threads (default: OpenCV's thread count); CNN inference threads "
        "(default: OpenVINO's choice)",
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
            out = _output(args.out, args.model)
            what = f"DPM {args.model.name}, threshold {threshold:g}"
        elif args.detector == "cnn":
            if args.model is None:
                raise ValueError(
                    f"--detector cnn needs --model PATH ({' or '.join(MODEL_SUFFIXES)})"
                )
            if args.upscale is not None:
                raise ValueError(
                    "--upscale is not a CNN option: the network's input follows the frame "
                    "(CnnConfig.input_heights)"
                )
            threshold = args.threshold if args.threshold is not None else CNN_CALIBRATION_THRESHOLD
            config = CnnConfig(threshold=threshold, threads=args.workers or 0)
            # The fit reads raw scores only: the identity mapping (p = the network's
            # confidence) stands in for the model's calibration, so that a broken file beside
            # the model does not stop its own replacement.
            detector = CnnDetector(
                load_network(args.model, config.threads), config, LogisticCalibration(1.0, 0.0)
            )
            out = _output(args.out, args.model)
            what = f"CNN {args.model.name}, confidence >= {threshold:g}"
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


def _output(out: Path | None, model: Path) -> Path:
    """Where a model's fit goes: ``out``, else ``<model>.calibration.json`` beside the model.

    Raises
    ------
    OSError
        If that file cannot be written; beside the model, also when the model's folder is
        marked read-only (no write permission bits: a shared data folder, which root could
        write into all the same), with a hint to pass ``--out``.
    """
    if out is not None:
        return output_file(out)
    beside = calibration_path(model)
    folder = beside.parent
    try:
        if folder.is_dir() and not folder.stat().st_mode & 0o222:
            raise PermissionError(f"cannot write {beside}: the folder {folder} is read-only")
        return output_file(beside)
    except OSError as error:
        raise type(error)(f"{error}; pass --out PATH") from None


if __name__ == "__main__":
    sys.exit(main())
