"""``vtrack track``'s output: a single target's box in every frame, as CSV rows or JSON lines.

CSV: the header ``frame,x,y,w,h,peak,psr,occluded``, then a row per frame: the video's frame
number (1-based: damaged frames leave their gap), the box (0-based corner, to 0.01 px), the
correlation peak (unclipped), the peak-to-sidelobe ratio and 0 or 1 for occluded. JSON lines:
an object per frame with ``frame``, ``box`` ``[x, y, w, h]``, ``peak``, ``psr`` and
``occluded``. The first frame, the given box, has no peak, PSR or occlusion: empty in CSV,
null in JSON.
"""

from __future__ import annotations

import json
from typing import Literal, TextIO

from tracking.tracks import FrameTracks
from tracking.types import TrackerOutput

CSV_HEADER = "frame,x,y,w,h,peak,psr,occluded"


class BoxRowWriter:
    """Rows of ``fmt`` written to ``out`` as frames are tracked (the CSV header with the first
    row: a run without frames writes nothing)."""

    def __init__(self, out: TextIO, fmt: Literal["csv", "json"]) -> None:
        self._out = out
        self._format = fmt
        self.rows = 0

    def write(self, number: int, tracks: FrameTracks, output: TrackerOutput | None) -> None:
        """The row of frame ``number``: the target's box in ``tracks`` (its one track) and, for
        every frame after the first, the correlation tracker's ``output``."""
        x, y, w, h = tracks.boxes[0].tolist()
        if self._format == "json":
            record = {
                "frame": number,
                "box": [x, y, w, h],
                "peak": None if output is None else output.peak,
                "psr": None if output is None else output.psr,
                "occluded": None if output is None else output.occluded,
            }
            row = json.dumps(record)
        else:
            if self.rows == 0:
                print(CSV_HEADER, file=self._out)
            scores = (
                ",,"
                if output is None
                else f"{output.peak:.4f},{output.psr:.2f},{int(output.occluded)}"
            )
            row = f"{number},{x:.2f},{y:.2f},{w:.2f},{h:.2f},{scores}"
        print(row, file=self._out)
        self.rows += 1
