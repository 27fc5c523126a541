"""MOTChallenge text: ``frame,id,x,y,w,h,score,-1,-1,-1`` per track and frame.

MOTChallenge's own conventions, so that the file scores against a ``gt.txt`` as it is (TrackEval,
the MOTChallenge devkit): frames count from 1 (the video's first frame is frame 1) and so do
pixels: ``x`` and ``y`` are the JSON result's 0-based corner plus 1
(:func:`tracking.datasets.mot.image_to_mot_boxes`).

The rows are those the benchmarks score, written by the same code
(:func:`tracking.evaluation.mot.track_rows` and :func:`~tracking.evaluation.mot.format_mot_rows`):
the same numbers to the same digits, in frame, id order, no id twice in a frame. Frames come in
order, each written as it comes; the estimates gap filling adds to earlier frames come late
(``write_filled``), so they wait in a scratch file and are merged into place at ``close``.
Memory stays at the filled rows, whatever the length of the video.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from api_schemas.analytics import AnalyticsEvent
from api_schemas.tracks import FrameTracksMessage
from service.frames import TimedFrame
from service.outputs.base import RunSummary, StreamInfo
from tracking.evaluation.mot import (
    RESULT_COLUMNS,
    check_unique_ids,
    format_mot_rows,
    track_rows,
)


def message_rows(message: FrameTracksMessage) -> np.ndarray:
    """The result rows (:func:`~tracking.evaluation.mot.track_rows`) of one frame's message."""
    tracks = message.tracks
    return track_rows(
        message.frame_index,
        np.array([t.track_id for t in tracks], dtype=np.int64),
        np.array([[t.box.x, t.box.y, t.box.w, t.box.h] for t in tracks], dtype=np.float64),
        np.array([t.score for t in tracks], dtype=np.float64),
    )


class MotWriter:
    def __init__(self, path: Path, info: StreamInfo) -> None:
        self.path = path
        self._file = path.open("w", encoding="utf-8")
        self._last_frame = -1  # the highest frame in the file
        self._late_path = path.with_suffix(".filled.partial")
        self._late: BinaryIO | None = None  # rows of frames already passed, as float64

    def write(
        self,
        frame: TimedFrame,
        message: FrameTracksMessage,
        events: Sequence[AnalyticsEvent] = (),
    ) -> None:
        self._append(message)

    def write_filled(self, message: FrameTracksMessage) -> None:
        self._append(message)

    def _append(self, message: FrameTracksMessage) -> None:
        rows = message_rows(message)
        check_unique_ids(rows)
        if message.frame_index > self._last_frame:
            self._file.write(format_mot_rows(rows))
            self._last_frame = message.frame_index
        elif len(rows):  # an earlier frame's: merged into place at close
            if self._late is None:
                self._late = self._late_path.open("wb")
            self._late.write(rows.astype(np.float64).tobytes())

    def close(self, summary: RunSummary) -> None:
        self._file.close()
        if self._late is not None:
            self._late.close()
            self._merge_late()
            self._late_path.unlink()
            self._late = None

    def _merge_late(self) -> None:
        """Rewrite the file with the late rows in frame, id order among the others.

        Raises
        ------
        ValueError
            If a late row's frame already has its track id.
        """
        late = np.fromfile(self._late_path, dtype=np.float64).reshape(-1, RESULT_COLUMNS)
        late = late[np.lexsort((late[:, 1], late[:, 0]))]
        check_unique_ids(late)
        lines = format_mot_rows(late).splitlines(keepends=True)
        keys = late[:, :2].astype(np.int64).tolist()
        merged = self.path.with_suffix(".txt.partial")
        k = 0
        with self.path.open(encoding="utf-8") as rows, merged.open("w", encoding="utf-8") as out:
            for line in rows:
                frame, track, _ = line.split(",", 2)
                key = [int(frame), int(track)]
                while k < len(keys) and keys[k] < key:
                    out.write(lines[k])
                    k += 1
                if k < len(keys) and keys[k] == key:
                    merged.unlink()
                    raise ValueError(f"track id {key[1]} appears more than once in frame {key[0]}")
                out.write(line)
            out.writelines(lines[k:])
        os.replace(merged, self.path)

    def abort(self) -> None:
        self._file.close()
        if self._late is not None:
            self._late.close()
        self._late_path.unlink(missing_ok=True)
