"""Detections from outside: MOTChallenge ``det.txt`` files and detections handed in per frame.

Public detections are how trackers are compared fairly (the same boxes for every tracker); in a
live stream an upstream detector publishes its boxes next to the frames. Both become the same
:class:`~tracking.detection.base.Detections` as our own detectors produce, and both implement
the :class:`~tracking.detection.base.Detector` protocol: ``detect(frame)`` returns the
detections of the *current frame index* and advances it (a sequence is read in order), or the
caller positions it with ``seek(index)``. Frame indices and boxes here are 0-based, as
everywhere in the project; MOTChallenge files count frames and pixels from 1, so index ``i``
reads the rows with ``frame == i + 1`` and a row's ``x, y`` become ``x - 1, y - 1``
(:func:`~tracking.datasets.mot.mot_to_image_boxes`; the file's pixel ``(1, 1)`` is the
image's ``(0, 0)``). They have no dense scores (``dense_scores`` returns ``None``) and no parts.

Probabilities: a calibration if one is given, else the file's confidence clipped to ``[0, 1]``
(the public detections of PETS09-S2L1 and TUD-Stadtmitte have confidences in ``[0.5, 1]``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from tracking.datasets.mot import mot_to_image_boxes, read_mot_rows
from tracking.detection.base import DenseScores, Detections
from tracking.detection.calibration import LogisticCalibration
from tracking.detection.regions import centres_inside, checked_region
from tracking.types import Box, is_int

__all__ = ["MotDetections", "SubmittedDetections", "detections_from_arrays"]


def detections_from_arrays(
    boxes: ArrayLike,
    scores: ArrayLike,
    probabilities: ArrayLike | None = None,
    *,
    calibration: LogisticCalibration | None = None,
    parts: ArrayLike | None = None,
    part_names: tuple[str, ...] = (),
) -> Detections:
    """Validated :class:`Detections` from plain arrays.

    Parameters
    ----------
    boxes:
        ``(N, 4)`` ``x, y, w, h`` in pixels; finite, with positive width and height.
    scores:
        ``(N,)`` finite raw scores.
    probabilities:
        ``(N,)`` in ``[0, 1]``; default: ``calibration`` of the scores if given, else the scores
        themselves, which must then lie in ``[0, 1]`` (raw scores of another range need one of
        the two: clipped, they would all read as certain or impossible).
    calibration:
        Maps scores to probabilities when ``probabilities`` is not given.
    parts:
        ``(N, P, 4)`` part boxes (NaN for a missing part) with ``P == len(part_names)``.
    part_names:
        Names of the parts.

    Raises
    ------
    ValueError
        With what was expected and what came, for any malformed input.
    """
    b = np.asarray(boxes, dtype=np.float64)
    if b.size == 0 and b.ndim <= 2:
        b = b.reshape(0, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise ValueError(f"boxes must have shape (N, 4), got {b.shape}")
    n = b.shape[0]
    s = np.asarray(scores, dtype=np.float64).reshape(-1)
    if s.shape != (n,):
        raise ValueError(f"scores must have shape ({n},), got {np.shape(scores)}")
    if not np.all(np.isfinite(b)):
        raise ValueError("boxes must be finite")
    if np.any(b[:, 2] <= 0) or np.any(b[:, 3] <= 0):
        raise ValueError("boxes must have positive width and height")
    if not np.all(np.isfinite(s)):
        raise ValueError("scores must be finite")
    if probabilities is not None:
        p = np.asarray(probabilities, dtype=np.float64).reshape(-1)
        if p.shape != (n,):
            raise ValueError(f"probabilities must have shape ({n},), got {np.shape(probabilities)}")
        if not np.all((p >= 0) & (p <= 1)):
            raise ValueError("probabilities must lie in [0, 1]")
    elif calibration is not None:
        p = calibration.probability(s)
    elif np.all((s >= 0) & (s <= 1)):
        p = s.copy()
    else:
        raise ValueError(
            f"scores are read as probabilities and must lie in [0, 1] (got {s.min():g} to "
            f"{s.max():g}): give raw scores with probabilities= or calibration="
        )
    if parts is None:
        q = np.zeros((n, len(part_names), 4))
        if part_names:
            q[:] = np.nan
    else:
        q = np.asarray(parts, dtype=np.float64)
        if q.shape != (n, len(part_names), 4):
            raise ValueError(f"parts must have shape ({n}, {len(part_names)}, 4), got {q.shape}")
    return Detections(boxes=b, scores=s, probabilities=p, parts=q, part_names=tuple(part_names))


def _in_region(detections: Detections, region: Box) -> Detections:
    """The detections whose box centre lies in ``region``."""
    return detections.subset(centres_inside(detections.boxes, region))


@dataclass(slots=True)
class _Cursor:
    """The frame index ``detect`` reads next."""

    index: int = 0

    def seek(self, index: int) -> None:
        if not is_int(index) or index < 0:
            raise ValueError(f"frame index must be a non-negative int, got {index!r}")
        self.index = int(index)


@dataclass(slots=True)
class MotDetections:
    """Detections read from a MOTChallenge ``det.txt``, handed out with 0-based boxes.

    Attributes
    ----------
    rows:
        ``(N, >= 7)`` the file's rows ``frame, id, x, y, w, h, conf, ...`` in file units (frames
        and pixels 1-based), as :func:`~tracking.datasets.mot.read_mot_rows` returns them;
        after construction, only the rows kept (confidence, positive size). The boxes of
        :meth:`for_frame` are these moved to 0-based pixels.
    calibration:
        Maps the confidence column to probabilities; ``None``: confidence clipped to ``[0, 1]``.
    min_confidence:
        Rows with a lower confidence are left out.
    dropped:
        How many of the rows given had no width or height (left out).
    """

    rows: np.ndarray
    calibration: LogisticCalibration | None = None
    min_confidence: float = -np.inf
    part_names: tuple[str, ...] = ()
    frame_indexed: ClassVar[bool] = True  # detect() reads frame after frame (Detector)
    dropped: int = field(init=False, default=0)
    _cursor: _Cursor = field(default_factory=_Cursor, repr=False)
    _by_frame: dict[int, np.ndarray] = field(init=False, repr=False)
    _boxes: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rows = np.asarray(self.rows, dtype=np.float64)
        if rows.ndim != 2 or rows.shape[1] < 7:
            raise ValueError(f"rows must have shape (N, >= 7), got {rows.shape}")
        rows = rows[rows[:, 6] >= self.min_confidence]
        sized = (rows[:, 4] > 0) & (rows[:, 5] > 0)
        self.rows, self.dropped = rows[sized], int(np.count_nonzero(~sized))
        rows = self.rows
        self._boxes = mot_to_image_boxes(rows[:, 2:6])
        frames = rows[:, 0].astype(np.int64)
        order = np.argsort(frames, kind="stable")
        uniq, start = np.unique(frames[order], return_index=True)
        bounds = np.append(start, order.size)
        self._by_frame = {int(f) - 1: order[bounds[i] : bounds[i + 1]] for i, f in enumerate(uniq)}

    @classmethod
    def from_file(
        cls,
        path: str | os.PathLike[str],
        calibration: LogisticCalibration | None = None,
        min_confidence: float = -np.inf,
    ) -> MotDetections:
        """Read a ``det.txt`` (raises ``MotFormatError``, a ValueError, naming a bad line)."""
        return cls(read_mot_rows(Path(path)), calibration, min_confidence)

    @property
    def num_frames(self) -> int:
        """1 + the largest 0-based frame index with a row (0 for an empty file)."""
        return max(self._by_frame, default=-1) + 1

    def for_frame(self, index: int) -> Detections:
        """Detections of 0-based frame ``index`` (file rows with ``frame == index + 1``), boxes
        with a 0-based corner (the file's ``x - 1, y - 1``)."""
        picked = self._by_frame.get(int(index), np.zeros(0, dtype=np.int64))
        confidence = self.rows[picked, 6]
        return detections_from_arrays(
            self._boxes[picked],
            confidence,
            None if self.calibration else np.clip(confidence, 0.0, 1.0),
            calibration=self.calibration,
        )

    def seek(self, index: int) -> None:
        """Make ``index`` (0-based) the frame the next :meth:`detect` returns."""
        self._cursor.seek(index)

    def detect(self, frame: np.ndarray) -> Detections:
        """Detections of the current frame index; advances the index (``frame`` is unused)."""
        out = self.for_frame(self._cursor.index)
        self._cursor.index += 1
        return out

    def detect_region(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> Detections:
        """Detections of the current frame whose centre lies in ``region`` (no advance)."""
        return _in_region(self.for_frame(self._cursor.index), checked_region(region))

    def dense_scores(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> DenseScores | None:
        """``None``: boxes from a file cannot be scored densely."""
        return None


@dataclass(slots=True)
class SubmittedDetections:
    """Detections the caller hands in per frame (e.g. received over Zenoh next to the frame).

    ``submit(i, boxes, scores)`` stores frame ``i``'s detections; ``detect(frame)`` returns those
    of the current frame index (empty if none were submitted) and advances the index, dropping
    everything older. At most ``max_pending`` future frames are held.
    """

    calibration: LogisticCalibration | None = None
    part_names: tuple[str, ...] = ()
    max_pending: int = 256
    frame_indexed: ClassVar[bool] = True  # detect() moves to the next frame (Detector)
    _cursor: _Cursor = field(default_factory=_Cursor, repr=False)
    _pending: dict[int, Detections] = field(default_factory=dict, repr=False)

    def submit(
        self,
        frame_index: int,
        boxes: ArrayLike,
        scores: ArrayLike,
        probabilities: ArrayLike | None = None,
        parts: ArrayLike | None = None,
    ) -> Detections:
        """Store the detections of 0-based ``frame_index``; returns them validated.

        Raises
        ------
        ValueError
            On malformed arrays (see :func:`detections_from_arrays`), a negative or past frame
            index, or more than ``max_pending`` frames waiting.
        """
        if not is_int(frame_index):
            raise ValueError(f"frame_index must be an int, got {frame_index!r}")
        if frame_index < self._cursor.index:
            raise ValueError(
                f"frame {frame_index} is already past (the next frame is {self._cursor.index})"
            )
        if frame_index not in self._pending and len(self._pending) >= self.max_pending:
            raise ValueError(f"more than {self.max_pending} frames of detections are waiting")
        detections = detections_from_arrays(
            boxes,
            scores,
            probabilities,
            calibration=self.calibration,
            parts=parts,
            part_names=self.part_names,
        )
        self._pending[int(frame_index)] = detections
        return detections

    def seek(self, index: int) -> None:
        """Make ``index`` the current frame; forgets detections of earlier frames."""
        self._cursor.seek(index)
        for key in [k for k in self._pending if k < self._cursor.index]:
            del self._pending[key]

    def current(self) -> Detections:
        """Detections submitted for the current frame (empty if none)."""
        return self._pending.get(self._cursor.index, Detections.empty(self.part_names))

    def detect(self, frame: np.ndarray) -> Detections:
        """The current frame's detections; then moves to the next frame."""
        out = self._pending.pop(self._cursor.index, Detections.empty(self.part_names))
        self.seek(self._cursor.index + 1)
        return out

    def detect_region(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> Detections:
        """The current frame's detections centred in ``region`` (no advance)."""
        return _in_region(self.current(), checked_region(region))

    def dense_scores(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> DenseScores | None:
        """``None``: handed-in boxes cannot be scored densely."""
        return None
