"""Logistic score calibration: fitting, files, and where detectors find them."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from scipy.special import expit

from tracking.detection.calibration import (
    CalibrationError,
    LogisticCalibration,
    calibration_path,
    fit_logistic,
    load_calibration,
)
from tracking.detection.dpm.detector import (
    DEFAULT_DPM_CALIBRATION,
    KNOWN_CALIBRATIONS,
    DpmConfig,
    DpmDetector,
)


@pytest.mark.parametrize(
    ("a", "b"),
    [
        (2.0, 1.0),  # DPM-like: p = 0.5 at s = -0.5
        (0.7, -3.0),  # a shallow slope and a rare positive class
        (5.0, 0.0),  # steep
    ],
)
def test_fit_recovers_known_parameters(a, b):
    rng = np.random.default_rng(0)
    scores = rng.normal(-b / a, 2.0, size=40_000)
    labels = rng.random(scores.size) < expit(a * scores + b)
    fitted = fit_logistic(scores, labels)
    # maximum-likelihood standard errors at this sample size are a few percent
    assert fitted.a == pytest.approx(a, rel=0.06)
    assert fitted.b == pytest.approx(b, abs=0.06 * max(1.0, abs(b)))


def test_probability_is_the_logistic_of_the_score():
    c = LogisticCalibration(a=2.0, b=-1.0)
    np.testing.assert_allclose(c.probability([0.5, 0.0, 100.0]), [0.5, expit(-1.0), 1.0])


def test_separable_data_still_gives_a_finite_fit():
    fitted = fit_logistic([-2.0, -1.0, 1.0, 2.0], [0, 0, 1, 1])
    assert np.isfinite(fitted.a) and fitted.a > 0
    assert fitted.probability(2.0) > 0.99


@pytest.mark.parametrize(
    ("scores", "labels", "message"),
    [
        ([1.0, 2.0], [1, 1], "both positives and negatives"),
        ([1.0, 2.0], [0, 2], "0 or 1"),
        ([1.0, np.nan], [0, 1], "finite"),
        ([1.0, 2.0, 3.0], [0, 1], "match"),
    ],
)
def test_bad_fitting_input(scores, labels, message):
    with pytest.raises(CalibrationError, match=message):
        fit_logistic(scores, labels)


def test_json_round_trip(tmp_path):
    c = LogisticCalibration(a=1.25, b=-0.5, source="test")
    path = c.save(tmp_path / "m.calibration.json")
    assert json.loads(path.read_text())["type"] == "logistic"
    assert load_calibration(path) == c


@pytest.mark.parametrize(
    "content",
    [
        "not json",
        '["a", "b"]',
        '{"a": 1.0}',
        '{"a": "x", "b": 1}',
        '{"type": "isotonic", "a": 1, "b": 2}',
        '{"a": Infinity, "b": 0}',
    ],
)
def test_bad_calibration_files(tmp_path, content):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(CalibrationError):
        load_calibration(path)


def test_missing_calibration_file(tmp_path):
    with pytest.raises(CalibrationError, match="not found"):
        load_calibration(tmp_path / "none.json")


def test_calibration_path_is_beside_the_model(tmp_path):
    assert calibration_path(tmp_path / "x" / "inriaperson_final.mat") == (
        tmp_path / "x" / "inriaperson_final.calibration.json"
    )


def test_dpm_detector_finds_its_calibration(tmp_path, inria_path, voc_path):
    # no file beside the (read-only, shared) models: the documented defaults
    assert DpmDetector.from_file(inria_path).calibration == DEFAULT_DPM_CALIBRATION
    assert DpmDetector.from_file(voc_path).calibration == KNOWN_CALIBRATIONS[("person", 6)]
    # a copy of the model with a calibration beside it
    model = tmp_path / "inriaperson_final.mat"
    shutil.copy(inria_path, model)
    LogisticCalibration(3.0, 0.5).save(calibration_path(model))
    assert DpmDetector.from_file(model).calibration == LogisticCalibration(3.0, 0.5)
    # a configured file wins
    other = LogisticCalibration(0.5, 0.1).save(tmp_path / "other.json")
    detector = DpmDetector.from_file(model, DpmConfig(calibration=other))
    assert detector.calibration == LogisticCalibration(0.5, 0.1)
