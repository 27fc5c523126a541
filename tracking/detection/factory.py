"""Build a person detector from a name or a path (the configuration's ``detector`` value)."""

from __future__ import annotations

import os
from pathlib import Path

from tracking.detection.base import Detector
from tracking.detection.calibration import LogisticCalibration
from tracking.detection.cnn import MODEL_SUFFIXES, CnnConfig, CnnDetector
from tracking.detection.dpm.detector import DpmConfig, DpmDetector
from tracking.detection.external import MotDetections, SubmittedDetections
from tracking.detection.hog_people import HogPeopleConfig, HogPeopleDetector

__all__ = ["DETECTOR_NAMES", "make_detector"]

DETECTOR_NAMES = ("default", "hog", "submitted", "cnn")
"""Names :func:`make_detector` accepts besides paths."""


def make_detector(
    name_or_path: str | os.PathLike[str],
    config: DpmConfig | HogPeopleConfig | CnnConfig | None = None,
    calibration: LogisticCalibration | None = None,
    *,
    model: str | os.PathLike[str] | None = None,
) -> Detector:
    """A detector by name or by file.

    Parameters
    ----------
    name_or_path:
        ``"default"`` or ``"hog"``: the embedded OpenCV HOG people detector (no file needed);
        ``"submitted"``: detections the caller hands in per frame; ``"cnn"``: the CNN detector
        with the network ``model``; a ``.mat`` path: the DPM engine with that voc-release5
        model; an ``.xml`` (OpenVINO IR) or ``.onnx`` path: the CNN detector with that
        network; a ``.txt`` path: MOTChallenge detections.
    config:
        ``DpmConfig`` for a DPM model, ``CnnConfig`` for a network, ``HogPeopleConfig`` for
        the embedded detector.
    calibration:
        Overrides the detector's score calibration.
    model:
        The network file of ``"cnn"``.

    Raises
    ------
    ValueError
        For an unknown name, a config of the wrong kind, or an unreadable file
        (``ModelFileError``, ``CnnModelError``, ``MotFormatError`` are ValueErrors).
    """
    key = os.fspath(name_or_path)
    if key == "cnn":
        if model is None:
            raise ValueError("detector 'cnn' needs its network: pass model=<.xml or .onnx path>")
        key = os.fspath(model)
    if key in ("default", "hog"):
        if config is not None and not isinstance(config, HogPeopleConfig):
            raise ValueError(f"the embedded detector takes a HogPeopleConfig, got {config!r}")
        hog = HogPeopleDetector(config or HogPeopleConfig())
        if calibration is not None:
            hog.calibration = calibration
        return hog
    if key == "submitted":
        return SubmittedDetections(calibration=calibration)
    path = Path(key)
    suffix = path.suffix.lower()
    if suffix == ".mat":
        if config is not None and not isinstance(config, DpmConfig):
            raise ValueError(f"a DPM model takes a DpmConfig, got {config!r}")
        dpm = DpmDetector.from_file(path, config or DpmConfig())
        if calibration is not None:
            dpm.calibration = calibration
        return dpm
    if suffix in MODEL_SUFFIXES:
        if config is not None and not isinstance(config, CnnConfig):
            raise ValueError(f"a CNN model takes a CnnConfig, got {config!r}")
        cnn = CnnDetector.from_file(path, config)
        if calibration is not None:
            cnn.calibration = calibration
        return cnn
    if suffix == ".txt":
        return MotDetections.from_file(path, calibration=calibration)
    raise ValueError(
        f"unknown detector {key!r}: expected one of {DETECTOR_NAMES}, a voc-release5 model "
        f"(.mat), a CNN model (.xml IR or .onnx) or MOTChallenge detections (.txt)"
    )
