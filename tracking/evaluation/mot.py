"""MOTChallenge files for multi-object tracking benchmarks: sequence info, ground truth, results.

Layout (MOTChallenge, Milan et al. 2016): ``<seq>/seqinfo.ini``, ``<seq>/img1/NNNNNN.jpg``,
``<seq>/gt/gt.txt`` and ``<seq>/det/det.txt``. Every text file has one object per line,

    frame, id, bb_left, bb_top, bb_width, bb_height, conf, x, y, z

with frames counted from 1. Result files have the same ten columns: the tracker's id in column 2,
its confidence in column 7 and ``-1, -1, -1`` for the world coordinates.

Pixel convention. MOTChallenge states that "all frame numbers, target IDs and bounding boxes are
1-based" (motchallenge.net/instructions): ``bb_left = 1`` is the first pixel column. The
project's boxes (:class:`tracking.types.Box`, :class:`tracking.detection.Detections`) have a
0-based top-left corner. So a box read from ``det.txt`` or ``gt.txt`` is moved by ``-1`` in x and
y before the tracker sees it (:func:`mot_to_image_boxes`, applied by
:class:`tracking.detection.MotDetections` and :attr:`tracking.detection.MotSequence.gt`), and a
box the tracker reports is moved by ``+1`` when it is written (:func:`track_rows`). ``gt.txt``,
``det.txt`` and our result files then share one convention, and IoU against the ground truth is
exact. A tracker that never looks at pixels (SORT, ByteTrack, OC-SORT) can take the file's boxes
as they are and write them back unchanged: the shift cancels.

Reading the text files, the exception and the two box conversions are those of
:mod:`tracking.datasets.mot` (re-exported here): :func:`read_mot_rows` returns rows in
file units, as written; :data:`MotFileError` is
:class:`~tracking.datasets.mot.MotFormatError`.

The evaluation itself (HOTA, CLEAR MOT, identity metrics) is TrackEval's; it runs in its own
environment (``benchmarks/_mot_env.py``) and reads the files written here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracking.datasets.mot import (
    MOT_PIXEL_ORIGIN,
    MotFormatError,
    image_to_mot_boxes,
    mot_to_image_boxes,
    read_mot_rows,
    read_seqinfo,
    seqinfo_frame_rate,
    seqinfo_whole_number,
)
from tracking.tracks import FrameTracks

__all__ = [
    "MOT_PIXEL_ORIGIN",
    "MotFileError",
    "SequenceInfo",
    "check_unique_ids",
    "find_mot_sequences",
    "format_mot_rows",
    "frame_rows",
    "ground_truth_rows",
    "image_to_mot_boxes",
    "limit_frames",
    "mot_to_image_boxes",
    "read_mot_rows",
    "read_sequence_info",
    "track_rows",
    "write_mot_file",
]

RESULT_COLUMNS = 10

MotFileError = MotFormatError
"""A MOTChallenge sequence folder or text file is missing or malformed (a ValueError)."""


@dataclass(frozen=True, slots=True)
class SequenceInfo:
    """One MOTChallenge sequence folder, as ``seqinfo.ini`` and the folder describe it.

    Attributes
    ----------
    path:
        The sequence folder.
    name:
        ``seqinfo.ini`` ``name``, else the folder name.
    frame_rate:
        Frames per second (``frameRate``).
    frame_paths:
        The ``seqLength`` images, frame 1 first (``imDir``/``*imExt``, in name order).
    width, height:
        Image size in pixels (``imWidth``, ``imHeight``); 0 when the file does not say.
    """

    path: Path
    name: str
    frame_rate: float
    frame_paths: tuple[Path, ...]
    width: int = 0
    height: int = 0

    def __len__(self) -> int:
        return len(self.frame_paths)

    @property
    def gt_path(self) -> Path:
        """``gt/gt.txt``."""
        return self.path / "gt" / "gt.txt"

    @property
    def det_path(self) -> Path:
        """The public detections, ``det/det.txt``."""
        return self.path / "det" / "det.txt"

    def timestamp(self, index: int) -> float:
        """Time of 0-based frame ``index`` in seconds: ``index / frame_rate``."""
        return index / self.frame_rate


def read_sequence_info(path: str | os.PathLike[str]) -> SequenceInfo:
    """Read a sequence folder's ``seqinfo.ini`` and list its frames.

    Raises
    ------
    MotFileError
        If the folder or its ``seqinfo.ini`` is missing, ``frameRate`` is missing or not a
        positive number, ``seqLength``, ``imWidth`` or ``imHeight`` is not a whole number, or
        there are fewer images than ``seqLength``; the message names the file and the key.
    """
    path = Path(path)
    if not path.is_dir():
        raise MotFileError(f"no such sequence folder: {path}")
    ini = path / "seqinfo.ini"
    if not ini.is_file():
        raise MotFileError(f"{path} has no seqinfo.ini, which every MOTChallenge sequence has")
    section = read_seqinfo(path)
    frame_rate = seqinfo_frame_rate(ini, section)
    if frame_rate is None:  # timestamps are frame indices over it: no default to fall back on
        raise MotFileError(f"{ini} has no frameRate")
    length = seqinfo_whole_number(ini, section, "seqLength")
    width = seqinfo_whole_number(ini, section, "imWidth") or 0
    height = seqinfo_whole_number(ini, section, "imHeight") or 0
    image_dir = path / section.get("imDir", "img1")
    suffix = section.get("imExt", ".jpg").lower()
    frames = sorted(p for p in image_dir.glob("*") if p.suffix.lower() == suffix)
    if length is None:
        length = len(frames)
    if length < 1 or len(frames) < length:
        raise MotFileError(
            f"{path}: seqLength {length} but {len(frames)} images {image_dir.name}/*{suffix}"
        )
    return SequenceInfo(
        path=path,
        name=section.get("name", path.name),
        frame_rate=frame_rate,
        frame_paths=tuple(frames[:length]),
        width=width,
        height=height,
    )


def find_mot_sequences(root: str | os.PathLike[str]) -> list[Path]:
    """Sequence folders at ``root``: ``root`` itself if it holds ``seqinfo.ini``, else its
    subfolders that do, in name order.

    Raises
    ------
    MotFileError
        If there is no such folder.
    """
    root = Path(root)
    if (root / "seqinfo.ini").is_file():
        return [root]
    if not root.is_dir():
        raise MotFileError(f"not a folder: {root}")
    found = sorted(p for p in root.iterdir() if (p / "seqinfo.ini").is_file())
    if not found:
        raise MotFileError(f"no MOTChallenge sequence (a folder with seqinfo.ini) in {root}")
    return found


def limit_frames(rows: np.ndarray, frames: int) -> np.ndarray:
    """The rows of the first ``frames`` frames (column 0 is the 1-based frame)."""
    return rows[rows[:, 0] <= frames]


def ground_truth_rows(
    path: str | os.PathLike[str], scale: float = 1.0, frames: int | None = None
) -> np.ndarray:
    """``frame, id, x, y, w, h`` rows of a MOTChallenge ``gt.txt`` with 0-based boxes scaled by
    ``scale`` (to a video made from the sequence at another size), of the first ``frames``
    frames (all when None)."""
    gt = read_mot_rows(path, min_columns=6)
    if frames is not None:
        gt = limit_frames(gt, frames)
    return np.column_stack([gt[:, :2], mot_to_image_boxes(gt[:, 2:6]) * scale])


def track_rows(
    frame_index: int, track_ids: object, boxes: object, scores: object | None = None
) -> np.ndarray:
    """Result rows of one frame, ``(N, 10)``: ``frame, id, x, y, w, h, score, -1, -1, -1``.

    Parameters
    ----------
    frame_index:
        0-based frame index (written as ``frame_index + 1``).
    track_ids:
        ``(N,)`` non-negative integer ids.
    boxes:
        ``(N, 4)`` ``x, y, w, h`` with a 0-based corner (written 1-based).
    scores:
        ``(N,)`` confidences; ``None`` writes 1.

    Raises
    ------
    ValueError
        For shapes that do not match, negative or non-integer ids, non-finite boxes.
    """
    ids = np.asarray(track_ids).reshape(-1)
    b = np.asarray(boxes, dtype=np.float64)
    if b.size == 0 and b.ndim <= 2:
        b = b.reshape(0, 4)
    n = ids.shape[0]
    if b.shape != (n, 4):
        raise ValueError(f"boxes must have shape ({n}, 4) for {n} ids, got {b.shape}")
    if n and (not np.all(np.isfinite(b))):
        raise ValueError("boxes must be finite")
    if n and (np.any(ids != np.round(ids)) or np.any(ids < 0)):
        raise ValueError(f"track ids must be non-negative integers, got {ids.tolist()}")
    s = np.ones(n) if scores is None else np.asarray(scores, dtype=np.float64).reshape(-1)
    if s.shape != (n,):
        raise ValueError(f"scores must have shape ({n},), got {s.shape}")
    rows = np.full((n, RESULT_COLUMNS), -1.0)
    rows[:, 0] = frame_index + 1
    rows[:, 1] = ids
    rows[:, 2:6] = image_to_mot_boxes(b)
    rows[:, 6] = s
    return rows


def frame_rows(tracks: FrameTracks) -> np.ndarray:
    """Result rows (:func:`track_rows`) of one frame's tracks: what the benchmarks score and the
    service's MOT download holds (both written by :func:`format_mot_rows`)."""
    return track_rows(tracks.frame_index, tracks.track_ids, tracks.boxes, tracks.scores)


def check_unique_ids(rows: np.ndarray) -> None:
    """Raise ValueError if an id appears twice in one frame (TrackEval refuses such files)."""
    if len(rows) == 0:
        return
    pairs = np.asarray(rows)[:, :2].astype(np.int64)
    unique, counts = np.unique(pairs, axis=0, return_counts=True)
    if np.any(counts > 1):
        frame, track = unique[np.argmax(counts > 1)]
        raise ValueError(f"track id {track} appears more than once in frame {frame}")


def format_mot_rows(rows: np.ndarray) -> str:
    """Rows ``(N, >= 7)`` as MOTChallenge text: integer frame and id, boxes to 1/100 pixel,
    the score to 5 decimals, ``-1`` for missing world coordinates; rows sorted by frame, id."""
    rows = np.asarray(rows, dtype=np.float64)
    if rows.size == 0:
        return ""
    if rows.ndim != 2 or rows.shape[1] < 7:
        raise ValueError(f"rows must have shape (N, >= 7), got {rows.shape}")
    full = np.full((rows.shape[0], RESULT_COLUMNS), -1.0)
    full[:, : min(rows.shape[1], RESULT_COLUMNS)] = rows[:, :RESULT_COLUMNS]
    full = full[np.lexsort((full[:, 1], full[:, 0]))]
    lines = [
        f"{int(r[0])},{int(r[1])},{r[2]:.2f},{r[3]:.2f},{r[4]:.2f},{r[5]:.2f},{r[6]:.5g},"
        f"{r[7]:g},{r[8]:g},{r[9]:g}"
        for r in full
    ]
    return "\n".join(lines) + "\n"


def write_mot_file(path: str | os.PathLike[str], rows: np.ndarray) -> Path:
    """Write result rows (``frame, id, x, y, w, h, score, ...``, file units) to ``path``,
    creating its folder; returns the path.

    Raises
    ------
    ValueError
        If an id appears twice in one frame.
    """
    path = Path(path)
    rows = np.asarray(rows, dtype=np.float64)
    if rows.size == 0:
        rows = rows.reshape(0, RESULT_COLUMNS)
    check_unique_ids(rows)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(format_mot_rows(rows), encoding="utf-8")
    return path
