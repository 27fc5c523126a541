"""Reading single-target sequences in the format of the OTB benchmark (Wu, Lim, Yang, CVPR 2013).

A sequence is a folder holding ``img/NNNN.jpg`` (frames in name order) and
``groundtruth_rect.txt``: one ``x,y,w,h`` per frame, 1-based pixel boxes, values separated by
commas, tabs or spaces. The thesis evaluates on this benchmark with its protocol (Danelljan 2013,
§5.1).

Ground truth is returned 0-based (``x - 1, y - 1``), matching :class:`tracking.types.Box`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracking.image_files import read_rgb
from tracking.types import Box

GROUND_TRUTH_FILE = "groundtruth_rect.txt"
IMAGE_FOLDER = "img"
IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp"})

_SEPARATORS = re.compile(r"[,\s]+")


class SequenceError(ValueError):
    """A sequence folder, its ground truth or one of its frames cannot be used."""


@dataclass(frozen=True, slots=True, eq=False)
class OtbSequence:
    """One OTB sequence: its frames and the ground-truth box of each.

    Attributes
    ----------
    name:
        Folder name, e.g. ``"Crossing"``.
    frame_paths:
        One image per ground-truth row, in frame order.
    ground_truth:
        ``(N, 4)`` float64, read-only: ``x, y, w, h`` per frame, 0-based top-left corner in
        pixels. Rows that are NaN or have a non-positive size mark frames without a label.
    """

    name: str
    frame_paths: list[Path]
    ground_truth: np.ndarray

    def __len__(self) -> int:
        return len(self.frame_paths)

    def box(self, index: int) -> Box:
        """The ground-truth box of frame ``index`` (0-based)."""
        x, y, w, h = (float(v) for v in self.ground_truth[index])
        return Box(x, y, w, h)


def parse_ground_truth(text: str, source: str = "<text>") -> np.ndarray:
    """Parse OTB ground truth: one 1-based ``x,y,w,h`` per line.

    Values may be separated by commas, tabs, spaces or a mix of them. Blank lines at the end are
    ignored; a blank line elsewhere would shift every later frame and is an error.

    Parameters
    ----------
    text:
        Contents of a ``groundtruth_rect.txt``.
    source:
        Name used in error messages (the file path).

    Returns
    -------
    np.ndarray
        ``(N, 4)`` float64 boxes with a 0-based top-left corner (1 subtracted from x and y).

    Raises
    ------
    SequenceError
        If a line does not hold exactly four numbers, or there is no line at all.
    """
    lines = text.rstrip().splitlines()
    rows: list[list[float]] = []
    for number, line in enumerate(lines, start=1):
        fields = [f for f in _SEPARATORS.split(line.strip()) if f]
        if len(fields) != 4:
            raise SequenceError(
                f"{source}, line {number}: expected 4 values x,y,w,h, got {len(fields)}: {line!r}"
            )
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            raise SequenceError(
                f"{source}, line {number}: expected 4 numbers x,y,w,h, got {line!r}"
            ) from None
    if not rows:
        raise SequenceError(f"{source}: no ground-truth boxes")
    boxes = np.asarray(rows, dtype=np.float64)
    boxes[:, :2] -= 1.0  # 1-based pixel coordinates -> 0-based
    return boxes


def load_otb_sequence(path: str | Path) -> OtbSequence:
    """Load the sequence in folder ``path``.

    If the folder holds more images than ground-truth rows, the first ``len(ground_truth)``
    frames are used; fewer images than rows is an error.

    Raises
    ------
    SequenceError
        If the folder, its ground-truth file or its images are missing, or the ground truth is
        malformed (the message names the line).
    """
    folder = Path(path)
    if not folder.is_dir():
        raise SequenceError(f"sequence folder {folder} does not exist")
    gt_file = folder / GROUND_TRUTH_FILE
    if not gt_file.is_file():
        raise SequenceError(f"{folder} has no {GROUND_TRUTH_FILE}")
    ground_truth = parse_ground_truth(gt_file.read_text(), source=str(gt_file))

    image_dir = folder / IMAGE_FOLDER
    frames = (
        sorted(p for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if image_dir.is_dir()
        else []
    )
    if not frames:
        raise SequenceError(f"{folder} has no images in {IMAGE_FOLDER}/")
    if len(frames) < len(ground_truth):
        raise SequenceError(
            f"{folder}: {len(ground_truth)} ground-truth rows but only {len(frames)} images"
        )
    ground_truth.setflags(write=False)
    return OtbSequence(
        name=folder.name,
        frame_paths=frames[: len(ground_truth)],
        ground_truth=ground_truth,
    )


def find_otb_sequences(root: str | Path) -> list[OtbSequence]:
    """Load every sub-folder of ``root`` that holds a ``groundtruth_rect.txt``, sorted by name.

    Raises
    ------
    SequenceError
        If ``root`` is not a folder, holds no sequence, or one of its sequences cannot be loaded.
    """
    root = Path(root)
    if not root.is_dir():
        raise SequenceError(f"OTB data folder {root} does not exist")
    folders = sorted(
        (p for p in root.iterdir() if (p / GROUND_TRUTH_FILE).is_file()), key=lambda p: p.name
    )
    if not folders:
        raise SequenceError(f"no OTB sequence (a folder with {GROUND_TRUTH_FILE}) in {root}")
    return [load_otb_sequence(folder) for folder in folders]


def read_frame(path: str | Path) -> np.ndarray:
    """Read one frame as an RGB ``uint8`` array of shape ``(H, W, 3)``.

    Raises
    ------
    SequenceError
        If the file is missing or is not an image OpenCV can decode.
    """
    image = read_rgb(path)
    if image is None:
        raise SequenceError(f"cannot read image {path} (missing or not a decodable image)")
    return image
