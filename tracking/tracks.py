"""What a tracking pipeline says about one frame: columns of numbers, one row per tracked object,
converted to `api_schemas` models only at the service edge (:func:`service.convert.frame_message`).

:class:`FrameTracks` holds a frame's tracks as arrays, in the style of supervision's
``Detections``: the trackers write them at once, the gap filler interpolates them whole, the MOT
text is formatted from them (:func:`tracking.evaluation.mot.frame_rows`). Callers who would
rather have objects iterate over it: each row comes out as a :class:`TrackEstimate` with its
:class:`PartEstimate` s.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from tracking.types import Box

__all__ = ["FrameTracks", "PartEstimate", "TrackEstimate"]


@dataclass(frozen=True, slots=True)
class PartEstimate:
    """One body part of a tracked person.

    Attributes
    ----------
    name:
        Stable part name (``"head"``, ``"left_shoulder"``...).
    x, y:
        Centre of the part in pixels.
    box:
        The part's box, when the model gives one.
    visible:
        ``False`` when the part is covered (by another person) or out of the frame; its position
        is then the model's prediction, not a measurement.
    measured:
        ``True`` when a measurement of this frame placed the part (a DPM part placement, or the
        peak of the part's own tracker); ``False`` when its position is the body model's
        prediction from the person's box, which is all a detector without parts gives.
    """

    name: str
    x: float
    y: float
    box: Box | None
    visible: bool
    measured: bool = False


@dataclass(frozen=True, slots=True)
class TrackEstimate:
    """One tracked object in one frame: a row of :class:`FrameTracks` as an object.

    Attributes
    ----------
    track_id:
        Stable id of the object within one pipeline (one video or one camera stream).
    box:
        Estimated box.
    score:
        Confidence in ``[0, 1]`` that the box holds the object.
    occluded:
        ``True`` while another, nearer object covers it.
    parts:
        Body parts, empty for trackers without parts.
    interpolated:
        ``True`` when the tracker did not report the object in this frame and the estimate
        was filled in afterwards between two frames where it did
        (:mod:`tracking.gap_filling`).
    """

    track_id: int
    box: Box
    score: float
    occluded: bool
    parts: tuple[PartEstimate, ...] = ()
    interpolated: bool = False


def _column(name: str, value: object, dtype: type, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as an array of ``dtype`` and ``shape``, or a ValueError naming the column."""
    array: np.ndarray = np.asarray(value, dtype=dtype)
    if array.size == 0 and shape[0] == 0:
        array = array.reshape(shape)
    if array.shape != shape:
        raise ValueError(f"FrameTracks {name} must have shape {shape}, got {array.shape}")
    return array


@dataclass(frozen=True, slots=True, eq=False)
class FrameTracks:
    """Everything tracked in one frame, as columns: row ``i`` of every array is one object.

    ``N`` is the number of objects, ``P`` the number of body parts (``len(part_names)``; 0 for
    trackers without parts). The constructor converts the columns to the dtypes below and checks
    their shapes (ValueError); :meth:`empty` makes a frame without tracks.

    Attributes
    ----------
    frame_index:
        0-based index of the frame in its video or stream (as processed; skipped stream frames
        leave gaps).
    timestamp:
        Capture time of the frame in seconds (video position for files, the camera's clock for
        streams).
    track_ids:
        ``(N,)`` int64, each object's stable id within its pipeline.
    boxes:
        ``(N, 4)`` float64 ``x, y, w, h`` in pixels, 0-based corner.
    scores:
        ``(N,)`` float64 confidence in ``[0, 1]`` that the box holds the object.
    occluded:
        ``(N,)`` bool, True while another, nearer object covers it.
    interpolated:
        ``(N,)`` bool, True for estimates filled in afterwards (:mod:`tracking.gap_filling`).
    part_names:
        The ``P`` part names, in the order of the part columns.
    part_xy:
        ``(N, P, 2)`` float64 part centres in pixels.
    part_boxes:
        ``(N, P, 4)`` float64 part boxes ``x, y, w, h``; NaN where the part has no box.
    part_visible:
        ``(N, P)`` bool, False where the part is covered or out of the frame
        (:attr:`PartEstimate.visible`).
    part_measured:
        ``(N, P)`` bool, True where this frame's image placed the part
        (:attr:`PartEstimate.measured`).
    """

    frame_index: int
    timestamp: float
    track_ids: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray
    occluded: np.ndarray
    interpolated: np.ndarray
    part_names: tuple[str, ...]
    part_xy: np.ndarray
    part_boxes: np.ndarray
    part_visible: np.ndarray
    part_measured: np.ndarray

    def __post_init__(self) -> None:
        ids = np.asarray(self.track_ids)
        if ids.ndim != 1:
            raise ValueError(f"FrameTracks track_ids must have shape (N,), got {ids.shape}")
        n, p = ids.shape[0], len(self.part_names)
        columns = {
            "track_ids": _column("track_ids", ids, np.int64, (n,)),
            "boxes": _column("boxes", self.boxes, np.float64, (n, 4)),
            "scores": _column("scores", self.scores, np.float64, (n,)),
            "occluded": _column("occluded", self.occluded, np.bool_, (n,)),
            "interpolated": _column("interpolated", self.interpolated, np.bool_, (n,)),
            "part_xy": _column("part_xy", self.part_xy, np.float64, (n, p, 2)),
            "part_boxes": _column("part_boxes", self.part_boxes, np.float64, (n, p, 4)),
            "part_visible": _column("part_visible", self.part_visible, np.bool_, (n, p)),
            "part_measured": _column("part_measured", self.part_measured, np.bool_, (n, p)),
        }
        object.__setattr__(self, "part_names", tuple(self.part_names))
        object.__setattr__(self, "timestamp", float(self.timestamp))
        for name, value in columns.items():
            object.__setattr__(self, name, value)

    @classmethod
    def empty(
        cls, frame_index: int, timestamp: float, part_names: Sequence[str] = ()
    ) -> FrameTracks:
        """A frame where nothing is tracked."""
        p = len(part_names)
        return cls(
            frame_index,
            timestamp,
            track_ids=np.zeros(0, np.int64),
            boxes=np.zeros((0, 4)),
            scores=np.zeros(0),
            occluded=np.zeros(0, bool),
            interpolated=np.zeros(0, bool),
            part_names=tuple(part_names),
            part_xy=np.zeros((0, p, 2)),
            part_boxes=np.zeros((0, p, 4)),
            part_visible=np.zeros((0, p), bool),
            part_measured=np.zeros((0, p), bool),
        )

    @classmethod
    def merge(cls, frames: Sequence[FrameTracks]) -> FrameTracks:
        """The rows of ``frames`` (at least one, all of one frame, index, time and part names)
        in one :class:`FrameTracks`, in the order given.

        Raises
        ------
        ValueError
            If ``frames`` is empty or its members disagree on the frame or the part names.
        """
        if not frames:
            raise ValueError("merging FrameTracks needs at least one")
        first = frames[0]
        for other in frames[1:]:
            if (other.frame_index, other.timestamp, other.part_names) != (
                first.frame_index,
                first.timestamp,
                first.part_names,
            ):
                raise ValueError(
                    f"cannot merge the tracks of frame {other.frame_index} "
                    f"({other.timestamp:.3f} s, parts {other.part_names}) into frame "
                    f"{first.frame_index} ({first.timestamp:.3f} s, parts {first.part_names})"
                )
        return cls(
            first.frame_index,
            first.timestamp,
            track_ids=np.concatenate([f.track_ids for f in frames]),
            boxes=np.concatenate([f.boxes for f in frames]),
            scores=np.concatenate([f.scores for f in frames]),
            occluded=np.concatenate([f.occluded for f in frames]),
            interpolated=np.concatenate([f.interpolated for f in frames]),
            part_names=first.part_names,
            part_xy=np.concatenate([f.part_xy for f in frames]),
            part_boxes=np.concatenate([f.part_boxes for f in frames]),
            part_visible=np.concatenate([f.part_visible for f in frames]),
            part_measured=np.concatenate([f.part_measured for f in frames]),
        )

    def __len__(self) -> int:
        return int(self.track_ids.shape[0])

    def __getitem__(self, index: int | slice | Sequence[int] | np.ndarray) -> FrameTracks:
        """The rows ``index`` selects (an int, a slice, an index array or a boolean mask of
        length N), as a :class:`FrameTracks` of the same frame; an int gives one row."""
        if isinstance(index, int | np.integer):
            index = [int(index)]
        return FrameTracks(
            self.frame_index,
            self.timestamp,
            track_ids=self.track_ids[index],
            boxes=self.boxes[index],
            scores=self.scores[index],
            occluded=self.occluded[index],
            interpolated=self.interpolated[index],
            part_names=self.part_names,
            part_xy=self.part_xy[index],
            part_boxes=self.part_boxes[index],
            part_visible=self.part_visible[index],
            part_measured=self.part_measured[index],
        )

    def __iter__(self) -> Iterator[TrackEstimate]:
        """Each row as a :class:`TrackEstimate`, in row order (part boxes with a NaN are
        None)."""
        has_box = ~np.isnan(self.part_boxes).any(axis=-1)
        rows = zip(
            self.track_ids.tolist(),
            self.boxes.tolist(),
            self.scores.tolist(),
            self.occluded.tolist(),
            self.interpolated.tolist(),
            self.part_xy.tolist(),
            self.part_boxes.tolist(),
            has_box.tolist(),
            self.part_visible.tolist(),
            self.part_measured.tolist(),
            strict=True,
        )
        for track_id, box, score, occluded, interpolated, xy, pboxes, boxed, seen, placed in rows:
            parts = tuple(
                PartEstimate(name, x, y, Box(*pbox) if has else None, visible, measured)
                for name, (x, y), pbox, has, visible, measured in zip(
                    self.part_names, xy, pboxes, boxed, seen, placed, strict=True
                )
            )
            yield TrackEstimate(track_id, Box(*box), score, occluded, parts, interpolated)
