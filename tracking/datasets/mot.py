"""MOTChallenge files: ``seqinfo.ini``, the one reader of their rows, the pixel convention, and
sequences as the detection benchmark and the calibration tool read them.

Layout (MOTChallenge 2015): ``<seq>/img1/NNNNNN.jpg`` (frame ``N``, 1-based),
``<seq>/gt/gt.txt`` and ``<seq>/det/det.txt`` with comma-separated rows
``frame, id, x, y, w, h, conf, ...`` (pixels, top-left corner, frame 1-based), and an optional
``seqinfo.ini``.

It imports nothing of the detectors or the evaluation: the service reads a folder's frame rate
(:mod:`service.frames`), :class:`~tracking.detection.external.MotDetections` reads ``det.txt``
and :mod:`tracking.evaluation.mot` writes results with it.

Ground truth: in MOT15-style ``gt.txt`` the 7th column is a flag, 0 meaning "ignore this row"
(MOT16+ also puts a class in column 8 and a visibility in column 9; rows whose class is not 1,
pedestrian, are ignored when the column is present and positive). In the PETS09-S2L1 and
TUD-Stadtmitte files shipped here every row has flag 1 and class -1, so every row counts.

Coordinates. MOTChallenge files are 1-based in frames *and* pixels ("all frame numbers, target
IDs and bounding boxes are 1-based", motchallenge.net/instructions): ``x = 1`` is the first pixel
column. The project's boxes (:class:`tracking.types.Box`,
:class:`~tracking.detection.base.Detections`) have a 0-based top-left corner. The move between
the two is made here and only here:

- :func:`read_mot_rows` returns a file's rows as written (file units: frames and pixels 1-based);
  use it for anything that is written back as MOTChallenge text (ground truth for TrackEval);
- :func:`mot_to_image_boxes` moves a file's ``x, y, w, h`` to 0-based image boxes (``x, y``
  minus 1). :attr:`MotSequence.gt` and :class:`~tracking.detection.external.MotDetections` hand
  out boxes moved by it, so ground truth, public detections and our detectors' boxes compare
  directly;
- :func:`image_to_mot_boxes` is its inverse, for writing boxes back
  (:func:`tracking.evaluation.mot.track_rows`).
"""

from __future__ import annotations

import configparser
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tracking.image_files import read_rgb

__all__ = [
    "MOT_PIXEL_ORIGIN",
    "MotFormatError",
    "MotSequence",
    "image_to_mot_boxes",
    "mot_to_image_boxes",
    "parse_mot_rows",
    "read_mot_rows",
    "read_seqinfo",
    "seqinfo_frame_rate",
    "seqinfo_whole_number",
]

MOT_PIXEL_ORIGIN = 1.0
"""Coordinate of the first pixel in MOTChallenge files (0 in the project's boxes)."""


class MotFormatError(ValueError):
    """A MOTChallenge file or folder is missing or malformed."""


def read_seqinfo(folder: str | os.PathLike[str]) -> Mapping[str, str]:
    """The ``[Sequence]`` entries of ``folder/seqinfo.ini`` (``name``, ``frameRate``,
    ``imDir``, ...; keys in any case), ``{}`` when the folder has no such file.

    Raises
    ------
    MotFormatError
        If the file cannot be parsed or has no ``[Sequence]`` section.
    """
    ini = Path(folder) / "seqinfo.ini"
    if not ini.is_file():
        return {}
    parser = configparser.ConfigParser()
    try:
        parser.read(ini, encoding="utf-8")
    except (configparser.Error, UnicodeDecodeError) as exc:
        raise MotFormatError(f"{ini}: {exc}") from exc
    if not parser.has_section("Sequence"):
        raise MotFormatError(f"{ini}: no [Sequence] section")
    return parser["Sequence"]


def seqinfo_frame_rate(ini: Path, section: Mapping[str, str]) -> float | None:
    """``frameRate`` of ``ini``'s ``[Sequence]`` (``None`` when the file has none).

    Raises
    ------
    MotFormatError
        If it is not a finite, positive number; the message names the file and the value.
    """
    if "frameRate" not in section:  # keys in any case, as configparser reads them
        return None
    text = section["frameRate"]
    try:
        rate = float(text)
    except ValueError:
        raise MotFormatError(
            f"{ini}: frameRate {text!r} is not a number of frames per second"
        ) from None
    if not (math.isfinite(rate) and rate > 0):
        raise MotFormatError(
            f"{ini}: frameRate {text!r} is not a positive number of frames per second"
        )
    return rate


def seqinfo_whole_number(ini: Path, section: Mapping[str, str], key: str) -> int | None:
    """Integer ``key`` of ``ini``'s ``[Sequence]`` (``None`` when the file has none).

    Raises
    ------
    MotFormatError
        If it is not a whole number; the message names the file, the key and the value.
    """
    if key not in section:
        return None
    text = section[key]
    try:
        return int(text)
    except ValueError:
        raise MotFormatError(f"{ini}: {key} {text!r} is not a whole number") from None


def read_mot_rows(path: str | os.PathLike[str], min_columns: int = 7) -> np.ndarray:
    """Rows of a MOTChallenge text file as a float64 array ``(N, C)``, ``C >= min_columns``, in
    file units: the numbers as written, frames and box corners 1-based (for 0-based boxes see
    :func:`mot_to_image_boxes`).

    Blank lines are skipped; separators may be commas or whitespace. Rows longer than the
    shortest are cut to its length. Frame numbers are whole numbers from 1.

    Raises
    ------
    MotFormatError
        If the file is missing or a line has fewer than ``min_columns`` numbers, a value that
        is not a number, or a frame number that is not a whole number from 1; the message names
        the line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MotFormatError(f"MOT file not found: {path}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise MotFormatError(f"cannot read {path}: {error}") from error
    return parse_mot_rows(text, min_columns, source=str(path))


def parse_mot_rows(text: str, min_columns: int = 7, source: str = "<text>") -> np.ndarray:
    """:func:`read_mot_rows` of MOTChallenge text already in memory (a downloaded result);
    ``source`` names it in errors."""
    rows: list[list[float]] = []
    width = None
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped:
            continue
        fields = stripped.replace(",", " ").split()
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise MotFormatError(
                f"{source}:{number}: expected numbers 'frame,id,x,y,w,h,conf,...', got {stripped!r}"
            ) from None
        if len(values) < min_columns:
            raise MotFormatError(
                f"{source}:{number}: expected at least {min_columns} columns, got {len(values)}"
            )
        if not all(np.isfinite(values[:min_columns])):
            raise MotFormatError(f"{source}:{number}: non-finite value in {stripped!r}")
        if values[0] < 1 or values[0] != int(values[0]):
            raise MotFormatError(
                f"{source}:{number}: the frame number {fields[0]} is not a whole number from 1"
            )
        width = len(values) if width is None else min(width, len(values))
        rows.append(values)
    if not rows:
        return np.zeros((0, min_columns))
    return np.array([r[:width] for r in rows], dtype=np.float64)


def mot_to_image_boxes(boxes: object) -> np.ndarray:
    """``(N, 4)`` ``x, y, w, h`` of a MOTChallenge file -> 0-based image boxes (x, y minus 1).

    Returns a new array; sizes are unchanged.
    """
    out = np.array(boxes, dtype=np.float64, copy=True).reshape(-1, 4)
    out[:, :2] -= MOT_PIXEL_ORIGIN
    return out


def image_to_mot_boxes(boxes: object) -> np.ndarray:
    """``(N, 4)`` 0-based image boxes -> MOTChallenge ``x, y, w, h`` (x, y plus 1)."""
    out = np.array(boxes, dtype=np.float64, copy=True).reshape(-1, 4)
    out[:, :2] += MOT_PIXEL_ORIGIN
    return out


@dataclass(frozen=True)
class MotSequence:
    """One MOTChallenge sequence folder.

    Attributes
    ----------
    path:
        The sequence folder.
    name:
        Its name (``seqinfo.ini`` ``name`` or the folder name).
    frames:
        Image files, frame 1 first.
    gt:
        Ground-truth boxes per 0-based frame index (``(M, 4)`` ``x, y, w, h``), 0-based pixels
        (the file's boxes moved by :func:`mot_to_image_boxes`).
    """

    path: Path
    name: str
    frames: tuple[Path, ...]
    gt: dict[int, np.ndarray] = field(repr=False)

    @classmethod
    def open(cls, path: str | os.PathLike[str]) -> MotSequence:
        """Read a sequence folder (frames and ground truth).

        Raises
        ------
        MotFormatError
            If the folder has no ``img1`` frames or no readable ``gt/gt.txt``.
        """
        path = Path(path)
        if not path.is_dir():
            raise MotFormatError(f"not a MOTChallenge sequence folder: {path}")
        info = read_seqinfo(path)
        name = info.get("name", path.name)
        ext = info.get("imExt", ".jpg")
        image_dir = info.get("imDir", "img1")
        frames = tuple(sorted((path / image_dir).glob(f"*{ext}")))
        if not frames:
            raise MotFormatError(f"{path}: no frames {image_dir}/*{ext}")
        rows = read_mot_rows(path / "gt" / "gt.txt")
        keep = rows[:, 6] != 0  # flag 0: ignore
        if rows.shape[1] >= 8:
            keep &= (rows[:, 7] <= 0) | (rows[:, 7] == 1)  # MOT16+: class 1 = pedestrian
        rows = rows[keep]
        boxes = mot_to_image_boxes(rows[:, 2:6])
        gt = {i: boxes[rows[:, 0] == i + 1] for i in range(len(frames))}
        return cls(path=path, name=name, frames=frames, gt=gt)

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def detections_file(self) -> Path:
        """The public detections, ``det/det.txt``."""
        return self.path / "det" / "det.txt"

    def read_frame(self, index: int) -> np.ndarray:
        """Frame ``index`` (0-based) as RGB uint8 ``(H, W, 3)``."""
        image = read_rgb(self.frames[index])
        if image is None:
            raise MotFormatError(f"cannot decode {self.frames[index]}")
        return image
