"""Score calibration: the probability that a detection with raw score ``s`` is a person.

A logistic mapping (Platt, "Probabilistic Outputs for Support Vector Machines", 1999):

    p(person | s) = 1 / (1 + exp(-(a s + b)))

fitted by maximum likelihood on detections labelled against ground truth (a detection is a
positive when it matches a ground-truth person, :func:`tracking.evaluation.detection.match_frame`).
Part II turns these probabilities into the image likelihood of its particle filter.

Calibrations are stored as small JSON files (``{"a": ..., "b": ..., ...}``) beside the model
they belong to: ``<model>.calibration.json`` next to ``<model>.mat`` (:func:`calibration_path`),
or wherever the user points the detector.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.special import expit

__all__ = [
    "CalibrationError",
    "LogisticCalibration",
    "calibration_path",
    "fit_logistic",
    "load_calibration",
]


class CalibrationError(ValueError):
    """A calibration file or fitting input is unusable."""


@dataclass(frozen=True, slots=True)
class LogisticCalibration:
    """``p = 1 / (1 + exp(-(a s + b)))``.

    Attributes
    ----------
    a:
        Slope per unit of raw score (positive: higher scores are likelier people).
    b:
        Offset; ``-b / a`` is the score at which ``p = 0.5``.
    source:
        Free text: what the mapping was fitted on.
    """

    a: float
    b: float
    source: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.a) and math.isfinite(self.b)):
            raise CalibrationError(f"a and b must be finite, got a={self.a}, b={self.b}")

    def probability(self, scores: object) -> np.ndarray:
        """Probabilities of raw ``scores`` (any shape), float64 in ``[0, 1]``."""
        s = np.asarray(scores, dtype=np.float64)
        return expit(self.a * s + self.b)

    def to_json(self) -> str:
        """The calibration as a JSON object."""
        return json.dumps({"type": "logistic", **asdict(self)}, indent=2) + "\n"

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write :meth:`to_json` to ``path``; returns the path."""
        path = Path(path)
        path.write_text(self.to_json(), encoding="utf-8")
        return path


def calibration_path(model_path: str | os.PathLike[str]) -> Path:
    """Where the calibration of a model file lives: ``<stem>.calibration.json`` beside it."""
    path = Path(model_path)
    return path.with_name(f"{path.stem}.calibration.json")


def load_calibration(path: str | os.PathLike[str]) -> LogisticCalibration:
    """Read a calibration JSON file.

    Raises
    ------
    CalibrationError
        If the file is missing, not JSON, or lacks finite ``a`` and ``b``.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrationError(f"calibration file not found: {path}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CalibrationError(f"{path} is not a JSON calibration file: {error}") from error
    if not isinstance(data, dict) or data.get("type", "logistic") != "logistic":
        raise CalibrationError(f"{path}: expected a JSON object with type 'logistic'")
    try:
        a, b = float(data["a"]), float(data["b"])
    except (KeyError, TypeError, ValueError) as error:
        raise CalibrationError(f"{path}: expected numbers 'a' and 'b', got {data}") from error
    return LogisticCalibration(a=a, b=b, source=str(data.get("source", "")))


def fit_logistic(
    scores: object,
    labels: object,
    *,
    regularization: float = 1e-6,
    max_iterations: int = 100,
    source: str = "",
) -> LogisticCalibration:
    """Maximum-likelihood logistic calibration by Newton's method.

    Minimises ``-sum_i [y_i log p_i + (1 - y_i) log(1 - p_i)] + r (a^2 + b^2) / 2`` with
    ``p_i = sigma(a s_i + b)``; the tiny ridge ``r`` keeps the fit finite when the classes are
    separable.

    Parameters
    ----------
    scores:
        ``(N,)`` raw scores.
    labels:
        ``(N,)`` 1 for a true detection, 0 for a false one (bools accepted).
    regularization:
        Ridge ``r >= 0`` on ``(a, b)``.
    max_iterations:
        Newton steps at most.
    source:
        Stored in the result's ``source``.

    Raises
    ------
    CalibrationError
        On mismatched shapes, non-finite scores, labels other than 0/1 or a single class.
    """
    s = np.asarray(scores, dtype=np.float64).reshape(-1)
    y = np.asarray(labels).reshape(-1)
    if y.shape != s.shape:
        raise CalibrationError(f"scores and labels must match, got {s.shape} and {y.shape}")
    if not np.all(np.isfinite(s)):
        raise CalibrationError("scores must be finite")
    if not np.all((y == 0) | (y == 1)):
        raise CalibrationError("labels must be 0 or 1")
    y = y.astype(np.float64)
    if y.sum() == 0 or y.sum() == y.size:
        raise CalibrationError(
            f"need both positives and negatives to fit, got {int(y.sum())} of {y.size} positive"
        )
    # Centre and scale the scores for conditioning; map back at the end.
    mu, sd = s.mean(), s.std() or 1.0
    x = np.column_stack([(s - mu) / sd, np.ones_like(s)])
    theta = np.array([1.0, math.log(y.mean() / (1.0 - y.mean()))])
    penalty = regularization * np.eye(2)
    for _ in range(max_iterations):
        p = expit(x @ theta)
        gradient = x.T @ (p - y) + penalty @ theta
        hessian = (x * (p * (1.0 - p))[:, None]).T @ x + penalty
        step = np.linalg.solve(hessian + 1e-12 * np.eye(2), gradient)
        theta -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    a = theta[0] / sd
    b = theta[1] - theta[0] * mu / sd
    return LogisticCalibration(a=float(a), b=float(b), source=source)
