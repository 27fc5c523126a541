"""The `Detector` contract: per frame, people with scores, parts and dense scores on request.

Every detector (the DPM engine, the embedded default, detections read from files or handed in
by a caller) returns the same :class:`Detections`; detectors that can score densely also return
:class:`DenseScores` for a region of interest, which the particle filter of Part II reads its
image likelihood from.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from tracking.types import Box


@dataclass(frozen=True, slots=True)
class Detections:
    """The people found in one frame.

    Attributes
    ----------
    boxes:
        ``(N, 4)`` float64, ``x, y, w, h`` in pixels, 0-based top-left corner.
    scores:
        ``(N,)`` raw detector scores (model units; higher is more confident).
    probabilities:
        ``(N,)`` calibrated probability that the box is a person, in ``[0, 1]``.
    parts:
        ``(N, P, 4)`` part boxes ``x, y, w, h`` for detectors with parts, else ``(N, 0, 4)``.
    part_names:
        ``P`` names with stable indices (``"head"``, ``"left_shoulder"``...).
    """

    boxes: np.ndarray
    scores: np.ndarray
    probabilities: np.ndarray
    parts: np.ndarray
    part_names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = self.boxes.shape[0]
        if self.boxes.shape != (n, 4):
            raise ValueError(f"boxes must have shape (N, 4), got {self.boxes.shape}")
        if not np.isfinite(self.boxes).all():  # parts may be NaN (not found); boxes may not
            raise ValueError("boxes must be finite numbers (x, y, w, h)")
        if self.scores.shape != (n,) or self.probabilities.shape != (n,):
            raise ValueError(
                f"scores and probabilities must have shape ({n},), got "
                f"{self.scores.shape} and {self.probabilities.shape}"
            )
        if self.parts.ndim != 3 or self.parts.shape[0] != n or self.parts.shape[2] != 4:
            raise ValueError(f"parts must have shape ({n}, P, 4), got {self.parts.shape}")
        if self.parts.shape[1] != len(self.part_names):
            raise ValueError(
                f"{self.parts.shape[1]} parts per detection but {len(self.part_names)} part names"
            )

    def __len__(self) -> int:
        return int(self.boxes.shape[0])

    def subset(self, keep: np.ndarray) -> Detections:
        """The detections selected by ``keep`` (a boolean mask or indices)."""
        return replace(
            self,
            boxes=self.boxes[keep],
            scores=self.scores[keep],
            probabilities=self.probabilities[keep],
            parts=self.parts[keep],
        )

    def scaled(self, factor: float) -> Detections:
        """The same detections with boxes and parts multiplied by ``factor``: detections made
        on frames ``factor`` times as large as the ones tracked."""
        return replace(self, boxes=self.boxes * factor, parts=self.parts * factor)

    @classmethod
    def empty(cls, part_names: tuple[str, ...] = ()) -> Detections:
        """No detections."""
        return cls(
            boxes=np.zeros((0, 4)),
            scores=np.zeros(0),
            probabilities=np.zeros(0),
            parts=np.zeros((0, len(part_names), 4)),
            part_names=part_names,
        )


@dataclass(frozen=True, slots=True)
class DenseScores:
    """Detector scores for every position and scale inside a region of interest.

    The particle filter evaluates its image likelihood at each particle's root centre and
    height with :meth:`lookup`; one call serves all particles of all people in the region.

    Attributes
    ----------
    region:
        The region of interest that was scored (clipped to the frame).
    heights:
        ``(L,)`` person heights in pixels that the score levels correspond to, ascending.
    levels:
        ``L`` arrays of raw scores, one per height; ``levels[l][i, j]`` scores a person of
        height ``heights[l]`` centred at ``origins[l] + (j, i) * strides[l]`` (x, y).
    origins:
        ``(L, 2)`` image position ``(x, y)`` of element ``[0, 0]`` of each level.
    strides:
        ``(L,)`` pixels between neighbouring elements of each level.
    part_names:
        Names of the parts whose best placements :attr:`part_offsets` holds, if any.
    part_offsets:
        Per level, ``(h_l, w_l, P, 2)`` offsets ``(dx, dy)`` in pixels of each part's best
        placement from the root centre, or an empty list for detectors without parts.
    """

    region: Box
    heights: np.ndarray
    levels: list[np.ndarray]
    origins: np.ndarray
    strides: np.ndarray
    part_names: tuple[str, ...] = ()
    part_offsets: list[np.ndarray] = field(default_factory=list)

    def lookup(self, centers: np.ndarray, heights: np.ndarray, outside: float = -np.inf):
        """Raw scores at root ``centers`` ``(K, 2)`` (x, y) and ``heights`` ``(K,)``.

        Each query reads the level of the nearest height (in log scale) at the nearest grid
        element; queries outside the scored region get ``outside``.

        Returns
        -------
        ndarray, shape (K,)
        """
        centers = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
        heights = np.asarray(heights, dtype=np.float64).reshape(-1)
        out = np.full(centers.shape[0], outside, dtype=np.float64)
        if len(self.levels) == 0 or centers.shape[0] == 0:
            return out
        log_h = np.log(self.heights)
        level = np.abs(np.log(np.maximum(heights, 1e-6))[:, None] - log_h[None, :]).argmin(axis=1)
        for index in np.unique(level):
            chosen = np.flatnonzero(level == index)
            grid = self.levels[index]
            col = np.rint((centers[chosen, 0] - self.origins[index, 0]) / self.strides[index])
            row = np.rint((centers[chosen, 1] - self.origins[index, 1]) / self.strides[index])
            inside = (row >= 0) & (row < grid.shape[0]) & (col >= 0) & (col < grid.shape[1])
            out[chosen[inside]] = grid[row[inside].astype(int), col[inside].astype(int)]
        return out


class Detector(Protocol):
    """What every person detector offers.

    Detections that come from outside by frame number (a ``det.txt``, boxes handed in) have a
    class attribute ``frame_indexed = True``: their :meth:`detect` answers for the next frame
    and moves on, and their :meth:`detect_region` for the current one without moving, so a
    caller must call :meth:`detect` once per frame (the people tracker's scheduler does, for
    them, on every frame: their searches cost nothing). The type checker holds the
    implementations to this protocol (``tests/protocol_conformance.py``).
    """

    part_names: tuple[str, ...]

    def detect(self, frame: np.ndarray) -> Detections:
        """People in the whole frame (RGB uint8 ``(H, W, 3)``)."""
        ...

    def detect_region(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> Detections:
        """People whose box centre lies inside ``region`` (a :class:`Box` or four numbers
        ``(x, y, w, h)``); much cheaper than :meth:`detect`.

        ``heights`` is the ``(min, max)`` height in pixels of the people to look for (the
        tracker asks for about a person's predicted height); ``None`` leaves it to the
        detector, whose default is made for a region around one person (a range of the
        region's own height: people much smaller than a large region are not looked for, so
        use :meth:`detect` for the whole frame). Detectors that do not search (boxes from
        outside) ignore it.
        """
        ...

    def dense_scores(
        self, frame: np.ndarray, region: Box, heights: tuple[float, float] | None = None
    ) -> DenseScores | None:
        """Scores for every position and scale in ``region`` for people ``heights`` tall (as
        in :meth:`detect_region`), or ``None`` when the detector cannot score densely (the
        tracker then builds its likelihood from the detections alone).
        """
        ...
